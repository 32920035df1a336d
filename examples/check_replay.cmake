# Runs `dmplatform replay RECORDING --out OUT` and checks that the replay's
# force trace is the recorded one tick for tick (replay.json "identical").
#   cmake -DDMPLATFORM=... -DRECORDING=.../recording.dmrec -DOUT=dir -P check_replay.cmake
file(REMOVE_RECURSE "${OUT}")
execute_process(COMMAND "${DMPLATFORM}" replay "${RECORDING}" --out "${OUT}"
                RESULT_VARIABLE rc OUTPUT_VARIABLE stdout ERROR_VARIABLE stderr)
message("${stdout}")
if(NOT rc EQUAL 0)
  message(FATAL_ERROR "dmplatform replay failed (${rc}):\n${stderr}")
endif()
file(READ "${OUT}/replay.json" report)
string(JSON identical GET "${report}" identical)
string(JSON compared GET "${report}" ticks_compared)
string(JSON records GET "${report}" records)
if(NOT identical OR NOT compared EQUAL records)
  message(FATAL_ERROR "the replay's force trace is not the recorded one:\n${report}")
endif()
message(STATUS "ok: ${compared} of ${records} recorded ticks replayed bit for bit")
