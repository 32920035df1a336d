# Runs the dental probing example (lockstep) and checks from summary.json:
#  - mirror and tongue: the tongue gives way (the skinned mesh dents > 1 mm)
#    under a force that stays under a rigid tongue's K times depth (5 N) and
#    builds smoothly (no step over 50 mN a tick); the root and anchors hold
#    what the mirror pushes (Newton, within 5 %); lifted, the tongue springs
#    back (< 0.05 mm left);
#  - scaler and calculus: three releases, each at the bond (1.5 N, within
#    the 10 mN a tick the push grows), each followed by a drop of the force
#    on the hand of more than 1 N within 20 ms;
#  - the outputs exist.
# -DEXAMPLE=program -DOUT=dir
include(${CMAKE_CURRENT_LIST_DIR}/../common/run_example.cmake)

dm_run_example(NAME run OUTPUTS mirror.dmrec scaler.dmrec mirror_forces.csv mirror_forces.png scaler_forces.csv
               scaler_forces.png tongue_pressed.ply)
string(JSON dent GET "${summary}" mirror max_dent_mm)
string(JSON left GET "${summary}" mirror dent_after_lift_mm)
string(JSON fmax GET "${summary}" mirror max_force_N)
string(JSON fstep GET "${summary}" mirror max_force_step_N)
if(dent LESS 1.0)
  message(FATAL_ERROR "mirror: the tongue dented ${dent} mm, expected > 1 mm")
endif()
if(fmax LESS 0.3 OR fmax GREATER 4.0)
  message(FATAL_ERROR "mirror: peak force ${fmax} N, expected 0.3..4 N (rigid: 5 N)")
endif()
if(fstep GREATER 0.05)
  message(FATAL_ERROR "mirror: the force jumped ${fstep} N in one tick")
endif()
string(JSON residual GET "${summary}" mirror hold_newton_residual)
if(residual GREATER 0.05)
  message(FATAL_ERROR "mirror: the root and anchors hold the tongue's load to ${residual} (relative), expected < 0.05")
endif()
if(left GREATER 0.05)
  message(FATAL_ERROR "mirror: ${left} mm of dent left after the lift")
endif()
string(JSON n LENGTH "${summary}" scaler releases)
if(NOT n EQUAL 3)
  message(FATAL_ERROR "scaler: ${n} releases, expected 3")
endif()
math(EXPR last "${n} - 1")
foreach(i RANGE ${last})
  string(JSON f GET "${summary}" scaler releases ${i} piece_force_N)
  string(JSON drop GET "${summary}" scaler releases ${i} drop_20ms_N)
  if(f LESS 1.5 OR f GREATER 1.52)
    message(FATAL_ERROR "scaler: release ${i} at ${f} N, expected the 1.5 N bond")
  endif()
  if(drop LESS 1.0)
    message(FATAL_ERROR "scaler: after release ${i} the force fell only ${drop} N in 20 ms")
  endif()
endforeach()
message(STATUS "ok")
