# dm_run_example(NAME name [ARGS ...] [OUTPUTS file ...]) runs ${EXAMPLE}
# --out ${OUT}/name ARGS in a fresh directory, fails on a non-zero exit or a
# missing output (summary.json always), and sets `summary` (its text) in the
# caller. The example checks (examples/*/check.cmake) include it.
function(dm_run_example)
  cmake_parse_arguments(R "" "NAME" "ARGS;OUTPUTS" ${ARGN})
  file(REMOVE_RECURSE ${OUT}/${R_NAME})
  execute_process(COMMAND ${EXAMPLE} --out ${OUT}/${R_NAME} ${R_ARGS}
                  RESULT_VARIABLE rc OUTPUT_VARIABLE out ERROR_VARIABLE err)
  message(STATUS "${R_NAME}: ${out}")
  if(NOT rc EQUAL 0)
    message(FATAL_ERROR "${EXAMPLE} --out ${OUT}/${R_NAME} ${R_ARGS} exited with ${rc}: ${err}")
  endif()
  foreach(f summary.json ${R_OUTPUTS})
    if(NOT EXISTS ${OUT}/${R_NAME}/${f})
      message(FATAL_ERROR "${R_NAME}: missing output ${f}")
    endif()
  endforeach()
  file(READ ${OUT}/${R_NAME}/summary.json text)
  set(summary "${text}" PARENT_SCOPE)
endfunction()
