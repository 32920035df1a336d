# Runs `dmplatform run SCENE --lockstep` and checks its outputs and physical
# outcomes from summary.json. Used by the examples' integration tests:
#   cmake -DDMPLATFORM=... -DSCENE=... -DOUT=... -DDURATION=... -DFRAMES=N
#         -DMIN_CONTACT_TICKS=N (FRAMES: at least that many frames)
#         -DMIN_FORCE=F -DMAX_FORCE=F -P check_scene_run.cmake
#         -DMOVED_BODY=name -DMIN_DISPLACEMENT=m (scenes with physics)
#         -DFLUID=name -DMIN_SUCTION_PARTICLES=N (scenes with "fluids"):
#         that fluid's account balanced and its suction tips took at least
#         N particles in all
#         -DVISION_FRAMES=N (scenes with a "vision" engine): its graph
#         stepped N frames and wrote vision/edge_pixels.csv with N rows
#         -DBONE_MAX_ERROR_MM=E -DBONE_MAX_DEPTH_MM=D (the bone-placement
#         renderer): the fragment started more than 5 mm from its plan and
#         ended within E mm of it, its voxels never more than D mm deep
#         -DIGTL_IMAGES=N (scenes with an "igtl" engine): it published at
#         least N IMAGE messages, and TRANSFORM and SENSOR messages
#         -DBURR_MIN_REMOVED_MM3=material=V[,material=V...] (the burr
#         renderer): at least V mm³ of each material drilled away, nothing of
#         a critical structure; -DBURR_MAX_REMOVED_MM3=V: at most V mm³ in
#         all; -DBURR_MIN_APPROACH_MM=D [-DBURR_MAX_APPROACH_MM=D]: the
#         burr's closest approach to the critical structures
#         -DMEMBRANE=name -DOBSTACLE=name -DMIN_LOAD_N=F -DMAX_LOAD_N=F
#         -DMAX_KINETIC_J=E (scenes with membranes): at the end the obstacle
#         carries between F and F newtons of the membrane downwards (-z),
#         the membrane's kinetic energy is at most E, and every implicit
#         step converged
#         -DHAPTICS=OFF: the scene has no haptics engine (no force trace,
#         no haptic thresholds)
#         -DSEGMENTATION_MIN_ML=V -DSEGMENTATION_MIN_PRECISION=P (scenes with
#         a "segmentation" engine): at least V mL painted, at least P of it
#         inside the reference region, no voxel outside the volume, the mask
#         written
#         -DPROGRAM=exe -DPROGRAM_ARGS=a,b -DSAME_FIGURES=path=key[,...]: the
#         example program, run with those arguments into OUT_program, writes
#         the same figures exactly — each scene summary path (members
#         joined by "/") equal to the program summary's key
# A lockstep run is run twice: the second run's force trace must equal the
# first's byte for byte, and its summary the first's in every figure but the
# measured times (engines, host, render, wall_s, the vision nodes' seconds):
# lockstep is bit-reproducible for every scene.
# Tele-operation scenes (a device with "serve") run in real time:
#         -DMODE=realtime -DMIN_ROUND_TRIP_MS=T: the served device's link
#         measured a round trip of at least T ms (p50), received a force
#         for at least 90 % of the haptic ticks, and its wave receiver, if
#         any, output no more energy than it received. -DMAX_FAULT_TICKS=N
#         allows N safety-fault ticks (real-time overruns on a shared
#         machine; default 0).
if(NOT DEFINED MODE)
  set(MODE lockstep)
endif()
if(NOT DEFINED HAPTICS)
  set(HAPTICS ON)
endif()
# dm_simulated_figures(OUT JSON): a summary less its measured times.
function(dm_simulated_figures out json)
  foreach(key engines host render wall_s)
    string(JSON json ERROR_VARIABLE absent REMOVE "${json}" ${key})
  endforeach()
  string(JSON nodes ERROR_VARIABLE absent LENGTH "${json}" vision nodes)
  if(NOT absent AND nodes GREATER 0)
    math(EXPR last "${nodes} - 1")
    foreach(i RANGE ${last})
      string(JSON json REMOVE "${json}" vision nodes ${i} seconds)
    endforeach()
  endif()
  set(${out} "${json}" PARENT_SCOPE)
endfunction()
# dm_named(OUT JSON NAME WHAT MEMBER...): the entry of the array at
# MEMBER... in JSON whose "name" is NAME, as JSON text; fails naming WHAT
# when there is none.
function(dm_named out json name what)
  string(JSON count ERROR_VARIABLE absent LENGTH "${json}" ${ARGN})
  if(NOT absent AND count GREATER 0)
    math(EXPR last "${count} - 1")
    foreach(i RANGE ${last})
      string(JSON entry GET "${json}" ${ARGN} ${i})
      string(JSON entryName GET "${entry}" name)
      if(entryName STREQUAL name)
        set(${out} "${entry}" PARENT_SCOPE)
        return()
      endif()
    endforeach()
  endif()
  message(FATAL_ERROR "no ${what} ${name} in the summary")
endfunction()
file(REMOVE_RECURSE "${OUT}")
execute_process(COMMAND "${DMPLATFORM}" run "${SCENE}" --${MODE} --duration ${DURATION} --out "${OUT}"
                RESULT_VARIABLE rc OUTPUT_VARIABLE stdout ERROR_VARIABLE stderr)
message("${stdout}")
if(NOT rc EQUAL 0)
  message(FATAL_ERROR "dmplatform run failed (${rc}):\n${stderr}")
endif()
set(expected summary.json)
if(HAPTICS)
  list(APPEND expected forces.csv forces.png)
endif()
foreach(f ${expected})
  if(NOT EXISTS "${OUT}/${f}")
    message(FATAL_ERROR "missing output ${OUT}/${f}")
  endif()
endforeach()
if(MODE STREQUAL "lockstep")
  file(REMOVE_RECURSE "${OUT}_rerun")
  execute_process(COMMAND "${DMPLATFORM}" run "${SCENE}" --lockstep --duration ${DURATION} --out "${OUT}_rerun"
                  RESULT_VARIABLE rc2 OUTPUT_QUIET ERROR_VARIABLE stderr2)
  if(NOT rc2 EQUAL 0)
    message(FATAL_ERROR "the second lockstep run failed (${rc2}):\n${stderr2}")
  endif()
  if(HAPTICS)
    execute_process(COMMAND ${CMAKE_COMMAND} -E compare_files "${OUT}/forces.csv" "${OUT}_rerun/forces.csv"
                    RESULT_VARIABLE differ)
    if(NOT differ EQUAL 0)
      message(FATAL_ERROR "two lockstep runs gave different force traces: ${OUT}/forces.csv, ${OUT}_rerun/forces.csv")
    endif()
  endif()
  file(READ "${OUT}/summary.json" first)
  file(READ "${OUT}_rerun/summary.json" second)
  dm_simulated_figures(first "${first}")
  dm_simulated_figures(second "${second}")
  string(JSON same EQUAL "${first}" "${second}")
  if(NOT same)
    message(FATAL_ERROR "two lockstep runs gave different summaries: ${OUT}/summary.json, ${OUT}_rerun/summary.json")
  endif()
  file(REMOVE_RECURSE "${OUT}_rerun")
endif()
file(READ "${OUT}/summary.json" summary)
string(JSON interrupted GET "${summary}" interrupted)
if(interrupted)
  message(FATAL_ERROR "the run reports an interruption")
endif()
# The host's CPU accounts over the run (Linux /proc/stat): steal can be 0, never negative.
string(JSON cpus GET "${summary}" host cpus)
string(JSON steal GET "${summary}" host cpu_steal_s)
if(cpus LESS 1 OR steal LESS 0)
  message(FATAL_ERROR "host: ${cpus} CPUs, ${steal} s stolen")
endif()
if(HAPTICS)
  # The force trace is in scene time in both modes: it starts at 0, not at
  # the machine's monotonic clock.
  file(STRINGS ${OUT}/forces.csv rows LIMIT_COUNT 2)
  list(GET rows 1 row)
  string(REGEX MATCH "^[^,]*" t0 "${row}")
  if(t0 GREATER 0.01)
    message(FATAL_ERROR "forces.csv starts at t = ${t0} s, expected scene time from 0")
  endif()
  string(JSON contact GET "${summary}" haptics contact_ticks)
  string(JSON ticks GET "${summary}" haptics ticks)
  string(JSON maxForce GET "${summary}" haptics max_force_N)
  string(JSON dropped GET "${summary}" haptics trace_dropped)
  string(JSON faults GET "${summary}" haptics safety_fault_ticks)
  if(contact LESS MIN_CONTACT_TICKS)
    message(FATAL_ERROR "only ${contact} of ${ticks} haptic ticks in contact (expected >= ${MIN_CONTACT_TICKS})")
  endif()
  if(maxForce LESS MIN_FORCE OR maxForce GREATER MAX_FORCE)
    message(FATAL_ERROR "max force ${maxForce} N outside [${MIN_FORCE}, ${MAX_FORCE}] N")
  endif()
  if(NOT DEFINED MAX_FAULT_TICKS)
    set(MAX_FAULT_TICKS 0)
  endif()
  # In real time, a tick the hypervisor kept from running is the host's fault,
  # not the program's: each stolen millisecond may add one late (fault) tick.
  # Steal is counted in whole scheduler ticks, so its text is a plain decimal.
  set(faultLimit ${MAX_FAULT_TICKS})
  if(MODE STREQUAL "realtime" AND steal MATCHES "^([0-9]+)(\\.([0-9]*))?$")
    set(stealWhole ${CMAKE_MATCH_1})
    string(SUBSTRING "${CMAKE_MATCH_3}000" 0 3 stealFrac)
    string(REGEX REPLACE "^0+([0-9])" "\\1" stealFrac "${stealFrac}")
    math(EXPR faultLimit "${MAX_FAULT_TICKS} + ${stealWhole} * 1000 + ${stealFrac}")
  endif()
  if(NOT dropped EQUAL 0 OR faults GREATER faultLimit)
    message(FATAL_ERROR "${dropped} trace samples dropped, ${faults} safety fault ticks "
                        "(limit ${faultLimit}: ${MAX_FAULT_TICKS} + 1 a millisecond of the ${steal} s stolen by the host)")
  endif()
  message(STATUS "ok: ${contact}/${ticks} ticks in contact, max force ${maxForce} N")
endif()
if(DEFINED FRAMES)
  string(JSON written GET "${summary}" render frames_written)
  # (30 Hz periods are rounded to whole nanoseconds: 1 s may hold 31 ticks.)
  if(written LESS FRAMES)
    message(FATAL_ERROR "${written} frames written, expected at least ${FRAMES}")
  endif()
  math(EXPR last "${FRAMES} - 1")
  string(LENGTH "${last}" digits)
  set(name "00000${last}")
  string(LENGTH "${name}" len)
  math(EXPR start "${len} - 5")
  string(SUBSTRING "${name}" ${start} 5 name)
  if(NOT EXISTS "${OUT}/frames/frame_${name}.png")
    message(FATAL_ERROR "missing last frame ${OUT}/frames/frame_${name}.png")
  endif()
endif()
if(DEFINED MIN_ROUND_TRIP_MS)
  string(JSON rtt GET "${summary}" teleop 0 round_trip p50_ms)
  string(JSON received GET "${summary}" teleop 0 received)
  if(rtt LESS MIN_ROUND_TRIP_MS)
    message(FATAL_ERROR "tele-operation round trip p50 ${rtt} ms, expected >= ${MIN_ROUND_TRIP_MS} ms")
  endif()
  # The simulator sends a force every haptic tick.
  math(EXPR minReceived "${ticks} * 9 / 10")
  if(received LESS minReceived)
    message(FATAL_ERROR "the console received ${received} forces for ${ticks} haptic ticks")
  endif()
  string(JSON wave ERROR_VARIABLE noWave GET "${summary}" teleop 0 wave)
  if(NOT noWave)
    string(JSON ein GET "${wave}" energy_in_J)
    string(JSON eout GET "${wave}" energy_out_J)
    if(eout GREATER ein)
      message(FATAL_ERROR "wave receiver output ${eout} J of ${ein} J received")
    endif()
  endif()
  message(STATUS "tele-operation: round trip p50 ${rtt} ms, ${received} forces received")
endif()
# Fluids: -DFLUID=name -DMIN_SUCTION_PARTICLES=N.
if(DEFINED FLUID)
  dm_named(fluid "${summary}" "${FLUID}" fluid physics fluids)
  string(JSON balanced GET "${fluid}" balanced)
  if(NOT balanced)
    message(FATAL_ERROR "fluid ${FLUID}: its account does not balance")
  endif()
  set(taken 0)
  string(JSON tips LENGTH "${fluid}" suction)
  if(tips GREATER 0)
    math(EXPR lastTip "${tips} - 1")
    foreach(k RANGE ${lastTip})
      string(JSON n GET "${fluid}" suction ${k} particles)
      math(EXPR taken "${taken} + ${n}")
    endforeach()
  endif()
  if(taken LESS MIN_SUCTION_PARTICLES)
    message(FATAL_ERROR "fluid ${FLUID}: suction took ${taken} particles, fewer than ${MIN_SUCTION_PARTICLES}")
  endif()
  message("fluid ${FLUID}: balanced, suction took ${taken} particles")
  if(NOT stdout MATCHES "fluid ${FLUID}: [0-9]+ particles")
    message(FATAL_ERROR "dmplatform did not print the fluid's line")
  endif()
endif()

# Physics: -DMOVED_BODY=name -DMIN_DISPLACEMENT=m: that dynamic body's
# centre of mass ended at least that far from where it started.
if(DEFINED MOVED_BODY)
  dm_named(body "${summary}" "${MOVED_BODY}" "dynamic body" physics bodies)
  string(JSON moved GET "${body}" displacement_m)
  if(moved LESS MIN_DISPLACEMENT)
    message(FATAL_ERROR "body ${MOVED_BODY} moved ${moved} m, expected at least ${MIN_DISPLACEMENT} m")
  endif()
  message(STATUS "physics: ${MOVED_BODY} moved ${moved} m")
endif()
if(DEFINED IGTL_IMAGES)
  string(JSON images GET "${summary}" igtl published image)
  string(JSON transforms GET "${summary}" igtl published transform)
  string(JSON sensors GET "${summary}" igtl published sensor)
  if(images LESS IGTL_IMAGES OR transforms LESS 1 OR sensors LESS 1)
    message(FATAL_ERROR "OpenIGTLink: ${images} IMAGE (expected >= ${IGTL_IMAGES}), ${transforms} TRANSFORM, "
                        "${sensors} SENSOR messages published")
  endif()
endif()
if(DEFINED VISION_FRAMES)
  string(JSON visionFrames GET "${summary}" vision frames)
  file(STRINGS "${OUT}/vision/edge_pixels.csv" visionRows REGEX "^[0-9]")
  list(LENGTH visionRows visionRowCount)
  if(NOT visionFrames EQUAL VISION_FRAMES OR NOT visionRowCount EQUAL VISION_FRAMES)
    message(FATAL_ERROR "vision: ${visionFrames} frames stepped, ${visionRowCount} CSV rows (expected ${VISION_FRAMES})")
  endif()
endif()
if(DEFINED BONE_MAX_ERROR_MM)
  string(JSON e0 GET "${summary}" bone_placement initial_error_m)
  string(JSON e1 GET "${summary}" bone_placement final_error_m)
  string(JSON depth GET "${summary}" bone_placement max_contact_depth_m)
  set(e1Limit "${BONE_MAX_ERROR_MM}e-3")
  set(depthLimit "${BONE_MAX_DEPTH_MM}e-3")
  if(e0 LESS 0.005 OR e1 GREATER e1Limit OR depth GREATER depthLimit)
    message(FATAL_ERROR "bone placement: error ${e0} m -> ${e1} m (expected > 0.005 -> <= ${e1Limit}), "
                        "contact depth ${depth} m (expected <= ${depthLimit})")
  endif()
  message(STATUS "bone placement: ${e0} m -> ${e1} m from the plan, contact depth ${depth} m")
endif()
if(DEFINED BURR_MIN_REMOVED_MM3)
  string(JSON forbidden GET "${summary}" burr removed_forbidden_m3)
  if(NOT forbidden EQUAL 0)
    message(FATAL_ERROR "burr: ${forbidden} m³ of a critical structure drilled away")
  endif()
  string(REPLACE "," ";" wanted "${BURR_MIN_REMOVED_MM3}")
  foreach(item ${wanted})
    string(REGEX MATCH "^([^=]+)=(.+)$" parsed "${item}")
    set(material ${CMAKE_MATCH_1})
    set(least "${CMAKE_MATCH_2}e-9")
    string(JSON removed GET "${summary}" burr removed_m3 ${material})
    if(removed LESS least)
      message(FATAL_ERROR "burr: ${removed} m³ of ${material} drilled away, expected at least ${least} m³")
    endif()
    message(STATUS "burr: ${removed} m³ of ${material} drilled away")
  endforeach()
  string(JSON total GET "${summary}" burr removed_total_m3)
  if(DEFINED BURR_MAX_REMOVED_MM3 AND total GREATER "${BURR_MAX_REMOVED_MM3}e-9")
    message(FATAL_ERROR "burr: ${total} m³ drilled away in all, expected at most ${BURR_MAX_REMOVED_MM3}e-9 m³")
  endif()
  string(JSON approach GET "${summary}" burr closest_approach_m)
  if(approach LESS "${BURR_MIN_APPROACH_MM}e-3"
     OR (DEFINED BURR_MAX_APPROACH_MM AND approach GREATER "${BURR_MAX_APPROACH_MM}e-3"))
    message(FATAL_ERROR "burr: closest approach ${approach} m to a critical structure, expected "
                        "[${BURR_MIN_APPROACH_MM}, ${BURR_MAX_APPROACH_MM}] mm")
  endif()
  message(STATUS "burr: closest approach ${approach} m")
endif()
if(DEFINED MEMBRANE)
  dm_named(membrane "${summary}" "${MEMBRANE}" membrane physics membranes)
  string(JSON kinetic GET "${membrane}" kinetic_energy_J)
  string(JSON unconverged GET "${membrane}" unconverged_steps)
  if(kinetic GREATER MAX_KINETIC_J OR NOT unconverged EQUAL 0)
    message(FATAL_ERROR "membrane ${MEMBRANE}: kinetic energy ${kinetic} J (expected <= ${MAX_KINETIC_J}), "
                        "${unconverged} unconverged steps")
  endif()
  dm_named(obstacle "${membrane}" "${OBSTACLE}" "obstacle of ${MEMBRANE}" obstacles)
  string(JSON load GET "${obstacle}" force_N 2)
  # The obstacle carries the membrane: the force on it points down.
  if(load GREATER "-${MIN_LOAD_N}" OR load LESS "-${MAX_LOAD_N}")
    message(FATAL_ERROR "membrane ${MEMBRANE}: ${OBSTACLE} carries ${load} N along z, "
                        "expected -[${MIN_LOAD_N}, ${MAX_LOAD_N}] N")
  endif()
  message(STATUS "membrane ${MEMBRANE}: ${OBSTACLE} carries ${load} N along z, kinetic energy ${kinetic} J")
endif()
if(DEFINED SEGMENTATION_MIN_ML)
  string(JSON ml GET "${summary}" segmentation painted_ml)
  string(JSON precision GET "${summary}" segmentation precision)
  string(JSON outside GET "${summary}" segmentation outside_volume_voxels)
  if(ml LESS SEGMENTATION_MIN_ML OR precision LESS SEGMENTATION_MIN_PRECISION OR NOT outside EQUAL 0
     OR NOT EXISTS "${OUT}/segmentation.nii.gz")
    message(FATAL_ERROR "segmentation: ${ml} mL painted (expected >= ${SEGMENTATION_MIN_ML}), precision "
                        "${precision} (expected >= ${SEGMENTATION_MIN_PRECISION}), ${outside} voxels outside the "
                        "volume, mask written: ${OUT}/segmentation.nii.gz")
  endif()
  message(STATUS "segmentation: ${ml} mL painted, precision ${precision}")
endif()
if(DEFINED PROGRAM)
  file(REMOVE_RECURSE "${OUT}_program")
  string(REPLACE "," ";" programArgs "${PROGRAM_ARGS}")
  execute_process(COMMAND "${PROGRAM}" ${programArgs} --out "${OUT}_program" RESULT_VARIABLE rc3 OUTPUT_QUIET
                  ERROR_VARIABLE stderr3)
  if(NOT rc3 EQUAL 0)
    message(FATAL_ERROR "the example program failed (${rc3}):\n${stderr3}")
  endif()
  file(READ "${OUT}_program/summary.json" programSummary)
  string(REPLACE "," ";" pairs "${SAME_FIGURES}")
  foreach(pair ${pairs})
    string(REGEX MATCH "^([^=]+)=(.+)$" parsed "${pair}")
    string(REPLACE "/" ";" scenePath "${CMAKE_MATCH_1}")
    set(programKey "${CMAKE_MATCH_2}")
    string(JSON mine GET "${summary}" ${scenePath})
    string(JSON theirs GET "${programSummary}" ${programKey})
    if(NOT mine STREQUAL theirs)
      message(FATAL_ERROR "the scene's ${CMAKE_MATCH_1} is ${mine}, the program's ${programKey} ${theirs}")
    endif()
  endforeach()
  message(STATUS "the same figures as ${PROGRAM}: ${SAME_FIGURES}")
endif()
