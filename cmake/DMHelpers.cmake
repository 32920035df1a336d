# Helpers shared by every module's CMakeLists.txt.

# Warnings (and -Werror in CI) and sanitizers, applied to our own targets only.
function(dm_target_options target)
  target_compile_options(${target} PRIVATE
    $<$<CXX_COMPILER_ID:GNU,Clang>:-Wall -Wextra -Wpedantic -Wshadow -Wnon-virtual-dtor
      -Wno-missing-field-initializers>)
  if(DM_WERROR)
    target_compile_options(${target} PRIVATE $<$<CXX_COMPILER_ID:GNU,Clang>:-Werror>)
  endif()
  if(DM_FUZZ)
    # Coverage for libFuzzer in every library of ours; the fuzz executables
    # add the fuzzer main themselves (Tests/fuzz/CMakeLists.txt).
    target_compile_options(${target} PRIVATE -fsanitize=fuzzer-no-link,address,undefined)
    target_link_options(${target} PRIVATE -fsanitize=address,undefined)
  endif()
  if(DM_SANITIZE)
    target_compile_options(${target} PRIVATE -fsanitize=${DM_SANITIZE} -fno-omit-frame-pointer
                                             -fno-sanitize-recover=all)
    target_link_options(${target} PRIVATE -fsanitize=${DM_SANITIZE})
  endif()
endfunction()

# dm_add_module(Core SOURCES a.cpp ... PUBLIC_DEPS ... PRIVATE_DEPS ...)
# Creates target DMCore, alias DM::Core, public headers in include/dm/<lower>/.
function(dm_add_module name)
  cmake_parse_arguments(M "" "" "SOURCES;PUBLIC_DEPS;PRIVATE_DEPS" ${ARGN})
  set(target DM${name})
  add_library(${target} ${M_SOURCES})
  add_library(DM::${name} ALIAS ${target})
  set_target_properties(${target} PROPERTIES EXPORT_NAME ${name} OUTPUT_NAME dm${name})
  target_compile_features(${target} PUBLIC cxx_std_20)
  target_include_directories(${target} PUBLIC
    $<BUILD_INTERFACE:${CMAKE_CURRENT_SOURCE_DIR}/include>
    $<INSTALL_INTERFACE:${CMAKE_INSTALL_INCLUDEDIR}>
    PRIVATE ${CMAKE_CURRENT_SOURCE_DIR}/src)
  target_link_libraries(${target} PUBLIC ${M_PUBLIC_DEPS} PRIVATE ${M_PRIVATE_DEPS})
  dm_target_options(${target})
  # Calls inside a module may be inlined even to its exported functions
  # (GCC otherwise assumes another library could interpose them): the
  # instruction-set versions that flatten a kernel (mass_spring.cpp) need it.
  target_compile_options(${target} PRIVATE $<$<CXX_COMPILER_ID:GNU>:-fno-semantic-interposition>)
  install(TARGETS ${target} EXPORT DMPlatformTargets
    ARCHIVE DESTINATION ${CMAKE_INSTALL_LIBDIR}
    LIBRARY DESTINATION ${CMAKE_INSTALL_LIBDIR}
    RUNTIME DESTINATION ${CMAKE_INSTALL_BINDIR})
  install(DIRECTORY include/ DESTINATION ${CMAKE_INSTALL_INCLUDEDIR})
endfunction()

# dm_add_test(NAME SOURCES ... LIBS ... [LABELS ...] [SERIAL gtest-filter])
# One GoogleTest executable; each TEST becomes a ctest case. The tests the
# SERIAL filter matches (real-time loops whose figures depend on having the
# cores) run alone (RUN_SERIAL).
function(dm_add_test name)
  cmake_parse_arguments(T "" "SERIAL" "SOURCES;LIBS;LABELS" ${ARGN})
  add_executable(${name} ${T_SOURCES})
  target_link_libraries(${name} PRIVATE ${T_LIBS} GTest::gtest GTest::gtest_main)
  dm_target_options(${name})
  include(GoogleTest)
  set(filter "")
  if(T_SERIAL)
    set(filter TEST_FILTER "-${T_SERIAL}")
    gtest_discover_tests(${name} DISCOVERY_TIMEOUT 60 TEST_FILTER "${T_SERIAL}"
      PROPERTIES LABELS "${T_LABELS}" ENVIRONMENT "DM_SOURCE_DIR=${PROJECT_SOURCE_DIR}" RUN_SERIAL TRUE)
  endif()
  gtest_discover_tests(${name} DISCOVERY_TIMEOUT 60 ${filter}
    PROPERTIES LABELS "${T_LABELS}" ENVIRONMENT "DM_SOURCE_DIR=${PROJECT_SOURCE_DIR}")
endfunction()

# dm_add_bench(NAME SOURCES ... LIBS ...): a benchmark program (never a test).
function(dm_add_bench name)
  cmake_parse_arguments(B "" "" "SOURCES;LIBS" ${ARGN})
  add_executable(${name} ${B_SOURCES})
  target_link_libraries(${name} PRIVATE ${B_LIBS})
  dm_target_options(${name})
endfunction()
