# test_core_links_alone (run by ctest with cmake -P): the solver core builds, links and runs
# without the application's JSON and without the oracle's CHOLMOD.
# Inputs: BUILD_DIR, CONFIG, INTERFACE_FILE (monolith_core's INTERFACE_LINK_LIBRARIES and
# INTERFACE_INCLUDE_DIRECTORIES, written at configure time), PROGRAM (the check's executable).

# 1. monolith_core's link and include interface names neither
file(READ ${INTERFACE_FILE} interface)
if(interface MATCHES "nlohmann|json|cholmod|CHOLMOD|suitesparse|SuiteSparse")
  message(FATAL_ERROR "monolith_core's interface names JSON or CHOLMOD:\n${interface}")
endif()

# 2. every core header compiles behind the poison folder, and a main links monolith_core alone
set(config_args "")
if(CONFIG)
  set(config_args --config ${CONFIG})
endif()
execute_process(COMMAND ${CMAKE_COMMAND} --build ${BUILD_DIR} --target core_links_alone ${config_args}
                RESULT_VARIABLE built OUTPUT_VARIABLE out ERROR_VARIABLE out)
if(NOT built EQUAL 0)
  message(FATAL_ERROR "building core_links_alone (every core header, monolith_core only) failed:\n${out}")
endif()

# 3. and it runs: one frame of a liquid beside a dynamic box, described in plain C++
execute_process(COMMAND ${PROGRAM} RESULT_VARIABLE ran OUTPUT_VARIABLE out ERROR_VARIABLE out)
message(STATUS "${out}")
if(NOT ran EQUAL 0)
  message(FATAL_ERROR "core_links_alone failed:\n${out}")
endif()
