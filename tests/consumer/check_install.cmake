# test_install_consumer (run by ctest with cmake -P): the installed core is usable on its own.
# Inputs: BUILD_DIR (the project's build folder, already built), CONFIG, SOURCE_DIR (this
# folder), WORK_DIR (scratch: the install prefix and the consumer's build), CXX_COMPILER.
#  1. cmake --install BUILD_DIR --prefix WORK_DIR/prefix (a fresh prefix)
#  2. the package files are there and no installed header includes the app, the pictures, the
#     oracle, nlohmann/json or CHOLMOD
#  3. tests/consumer configures with find_package(Monolith) against that prefix only, builds and
#     runs (its own Jacobi-PCG against the library's pressure solve)

set(prefix ${WORK_DIR}/prefix)
file(REMOVE_RECURSE ${WORK_DIR})
file(MAKE_DIRECTORY ${WORK_DIR})

set(config_args "")
if(CONFIG)
  set(config_args --config ${CONFIG})
endif()
execute_process(COMMAND ${CMAKE_COMMAND} --build ${BUILD_DIR} --target monolith_core ${config_args}
                RESULT_VARIABLE rc OUTPUT_VARIABLE out ERROR_VARIABLE out)
if(NOT rc EQUAL 0)
  message(FATAL_ERROR "building monolith_core failed:\n${out}")
endif()
execute_process(COMMAND ${CMAKE_COMMAND} --install ${BUILD_DIR} --prefix ${prefix} ${config_args}
                RESULT_VARIABLE rc OUTPUT_VARIABLE out ERROR_VARIABLE out)
if(NOT rc EQUAL 0)
  message(FATAL_ERROR "cmake --install failed:\n${out}")
endif()

# 2. the package and the headers
file(GLOB_RECURSE config_files ${prefix}/*/MonolithConfig.cmake)
file(GLOB_RECURSE version_files ${prefix}/*/MonolithConfigVersion.cmake)
file(GLOB_RECURSE libraries ${prefix}/*libmonolith_core.a)
if(NOT config_files OR NOT version_files OR NOT libraries)
  message(FATAL_ERROR "the install lacks MonolithConfig.cmake, its version file or libmonolith_core.a under ${prefix}")
endif()
if(NOT EXISTS ${prefix}/include/monolith/reference/coupling/monolithic_system.hpp)
  message(FATAL_ERROR "headers are not under ${prefix}/include/monolith/reference/...")
endif()
file(GLOB_RECURSE headers ${prefix}/include/*)
list(LENGTH headers header_count)
set(problems "")
foreach(header ${headers})
  if(NOT header MATCHES "\\.hpp$")
    list(APPEND problems "not a header: ${header}")
    continue()
  endif()
  if(header MATCHES "/reference/(app|viz|oracle)/")
    list(APPEND problems "installed outside the core: ${header}")
  endif()
  file(STRINGS ${header} includes REGEX "^[ \t]*#[ \t]*include")
  foreach(line ${includes})
    if(line MATCHES "reference/(app|viz|oracle)/|nlohmann|json\\.hpp|cholmod|SuiteSparse|suitesparse")
      list(APPEND problems "${header}: ${line}")
    endif()
  endforeach()
endforeach()
if(problems)
  string(REPLACE ";" "\n" problems "${problems}")
  message(FATAL_ERROR "installed headers reach beyond the core:\n${problems}")
endif()
message(STATUS "installed ${header_count} headers, the core library and the package into ${prefix}")

# 3. the consumer, configured against the prefix alone
execute_process(COMMAND ${CMAKE_COMMAND} -S ${SOURCE_DIR} -B ${WORK_DIR}/build
                        -DCMAKE_PREFIX_PATH=${prefix} -DCMAKE_CXX_COMPILER=${CXX_COMPILER}
                        -DCMAKE_BUILD_TYPE=Release
                RESULT_VARIABLE rc OUTPUT_VARIABLE out ERROR_VARIABLE out)
if(NOT rc EQUAL 0)
  message(FATAL_ERROR "configuring tests/consumer against ${prefix} failed:\n${out}")
endif()
execute_process(COMMAND ${CMAKE_COMMAND} --build ${WORK_DIR}/build
                RESULT_VARIABLE rc OUTPUT_VARIABLE out ERROR_VARIABLE out)
if(NOT rc EQUAL 0)
  message(FATAL_ERROR "building tests/consumer failed:\n${out}")
endif()
execute_process(COMMAND ${WORK_DIR}/build/consumer RESULT_VARIABLE rc OUTPUT_VARIABLE out ERROR_VARIABLE out)
message(STATUS "${out}")
if(NOT rc EQUAL 0)
  message(FATAL_ERROR "the consumer failed:\n${out}")
endif()
