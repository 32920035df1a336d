# Runs the needle insertion example (lockstep) and checks the force the
# hand felt:
#  - two membranes broken, the skin's and the muscle's fascia (the fat has
#    none), in that order; the tip was 0-10 mm deep at the first (the skin
#    tents in ahead of it) and 15-20 mm at the second (the fascia at 15 mm);
#  - the largest force felt before each within 5 % under its threshold (the
#    skin's 1.2 N alone; at the fascia 0.8 N plus the friction and cutting
#    of the shaft already in, so at least 0.8 N): the pop is felt in the
#    tick the tip's force reaches the threshold, and that tick already has
#    the lower force after it;
#  - in the muscle the force grows with depth at the muscle's friction
#    (40 N/m, within 5 %);
#  - the outputs exist.
# -DEXAMPLE=program -DOUT=dir
include(${CMAKE_CURRENT_LIST_DIR}/../common/run_example.cmake)

# A decimal string as an integer number of millionths (CMake has no floats).
function(to_micro out value)
  if(NOT value MATCHES "^(-?)([0-9]+)\\.?([0-9]*)")
    message(FATAL_ERROR "not a number: ${value}")
  endif()
  set(sign "${CMAKE_MATCH_1}")
  set(int "${CMAKE_MATCH_2}")
  string(SUBSTRING "${CMAKE_MATCH_3}000000" 0 6 frac)
  math(EXPR micro "${sign}(${int} * 1000000 + 1${frac} - 1000000)")
  set(${out} ${micro} PARENT_SCOPE)
endfunction()
function(require_between name value lo hi)
  to_micro(v "${value}")
  to_micro(l "${lo}")
  to_micro(h "${hi}")
  if(v LESS l OR v GREATER h)
    message(FATAL_ERROR "${name} = ${value}; expected ${lo} to ${hi}")
  endif()
endfunction()

dm_run_example(NAME layered OUTPUTS force.csv force.png)
string(JSON punctures GET "${summary}" punctures)
if(NOT punctures EQUAL 2)
  message(FATAL_ERROR "${punctures} membranes broken; expected 2 (skin, fascia)")
endif()
string(JSON first GET "${summary}" membranes 0 layer)
string(JSON second GET "${summary}" membranes 1 layer)
if(NOT first STREQUAL "skin" OR NOT second STREQUAL "muscle")
  message(FATAL_ERROR "membranes broken in ${first}, ${second}; expected skin, muscle")
endif()
string(JSON d1 GET "${summary}" membranes 0 depth_m)
string(JSON d2 GET "${summary}" membranes 1 depth_m)
string(JSON f1 GET "${summary}" membranes 0 peak_force_N)
string(JSON f2 GET "${summary}" membranes 1 peak_force_N)
string(JSON slope GET "${summary}" muscle_friction fitted_force_slope_N_per_m)
require_between("tip depth when the skin broke (m)" ${d1} 0 0.010)
require_between("tip depth when the fascia broke (m)" ${d2} 0.015 0.020)
require_between("force felt before the skin broke (N)" ${f1} 1.14 1.2)
require_between("force felt before the fascia broke (N)" ${f2} 0.8 1.5)
require_between("force slope in the muscle (N/m)" ${slope} 38 42)
message(STATUS "ok: membranes at ${d1} m (${f1} N) and ${d2} m (${f2} N), slope in the muscle ${slope} N/m")
