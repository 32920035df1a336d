# Runs the tissue indentation example (lockstep) and checks its inverse fit:
#  - two tissues (12 kPa, 40 ms and 6 kPa, 15 ms), each simulated, measured
#    with Gaussian noise and fitted from a start far away (5 kPa, 10 ms):
#    E and beta recovered within 5 %, the residual RMS at the noise level
#    (0.8-1.2 sigma: the model explains the curve, the fit does not chase
#    the noise);
#  - the first run's measurement fitted again through --measured gives the
#    same coefficients (the CSV path);
#  - a malformed curve is refused with its file and line;
#  - the outputs exist.
# -DEXAMPLE=program -DOUT=dir
include(${CMAKE_CURRENT_LIST_DIR}/../common/run_example.cmake)

function(check_fit name youngs beta)
  dm_run_example(NAME ${name} ARGS --youngs ${youngs} --beta ${beta} --noise 0.01 --seed 7
                 OUTPUTS curve.csv measured.csv curve.png forces.png)
  string(JSON eE GET "${summary}" relative_error youngs_modulus)
  string(JSON eB GET "${summary}" relative_error beta)
  string(JSON ratio GET "${summary}" rms_over_noise)
  if(eE GREATER 0.05 OR eB GREATER 0.05)
    message(FATAL_ERROR "${name}: relative errors E ${eE}, beta ${eB}; expected <= 0.05")
  endif()
  if(ratio LESS 0.8 OR ratio GREATER 1.2)
    message(FATAL_ERROR "${name}: residual RMS is ${ratio} noise sigma; expected 0.8-1.2")
  endif()
  string(JSON fitE GET "${summary}" fit youngs_modulus_Pa)
  string(JSON fitB GET "${summary}" fit beta_s)
  set(fitE ${fitE} PARENT_SCOPE)
  set(fitB ${fitB} PARENT_SCOPE)
  message(STATUS "${name}: E ${fitE} Pa (error ${eE}), beta ${fitB} s (error ${eB}), RMS/noise ${ratio}")
endfunction()

check_fit(stiff 12000 0.04)
set(stiffE ${fitE})
set(stiffB ${fitB})
check_fit(soft 6000 0.015)

# The measurement fitted again from its CSV.
dm_run_example(NAME refit ARGS --measured ${OUT}/stiff/measured.csv)
string(JSON refitE GET "${summary}" fit youngs_modulus_Pa)
string(JSON refitB GET "${summary}" fit beta_s)
# (CMake has no float arithmetic: compare the printed values' leading digits.)
string(SUBSTRING "${refitE}" 0 7 a)
string(SUBSTRING "${stiffE}" 0 7 b)
string(SUBSTRING "${refitB}" 0 6 c)
string(SUBSTRING "${stiffB}" 0 6 d)
if(NOT a STREQUAL b OR NOT c STREQUAL d)
  message(FATAL_ERROR "--measured fit E ${refitE} beta ${refitB}, simulated run's fit E ${stiffE} beta ${stiffB}")
endif()

# A malformed curve names its file and line.
file(WRITE ${OUT}/bad.csv "t,displacement_m,force_N\n0,0,0\n0.01,0.00003,abc\n")
execute_process(COMMAND ${EXAMPLE} --measured ${OUT}/bad.csv --out ${OUT}/bad
                RESULT_VARIABLE rc ERROR_VARIABLE err OUTPUT_QUIET)
if(NOT rc EQUAL 1 OR NOT err MATCHES "bad.csv:3")
  message(FATAL_ERROR "a malformed curve gave exit ${rc} and: ${err}")
endif()
message(STATUS "ok")
