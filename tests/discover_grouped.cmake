# Script mode (cmake -P), run after a test executable is built: lists its GoogleTest tests and
# writes the CTest file that registers them.
#
# Value-parameterized tests (Prefix/Suite.Name/Param) are registered as one CTest test per
# parameter, "<executable>/<Param>", that runs all of that parameter's tests in one process: the
# parameter names a dataset, and the test support caches each built dataset per process
# (tests/support/datasets.cpp, meshes.cpp), so the dataset is built once instead of once per
# test. Every other test is registered on its own, as gtest_discover_tests would.
#
# Inputs: TEST_EXECUTABLE, TEST_FILE (the CTest file to write), TEST_ENVIRONMENT.

cmake_minimum_required(VERSION 3.20)

execute_process(COMMAND "${TEST_EXECUTABLE}" --gtest_list_tests
                OUTPUT_VARIABLE listing RESULT_VARIABLE result TIMEOUT 60)
if(NOT result EQUAL 0)
  message(FATAL_ERROR "${TEST_EXECUTABLE} --gtest_list_tests failed (${result}):\n${listing}")
endif()

get_filename_component(executable_name "${TEST_EXECUTABLE}" NAME)
string(REPLACE ";" "\\;" listing "${listing}")
string(REPLACE "\n" ";" lines "${listing}")
set(singles "")
set(groups "")
set(suite "")
foreach(line IN LISTS lines)
  string(REGEX REPLACE " *#.*$" "" line "${line}")
  if(line STREQUAL "")
    continue()
  endif()
  if(NOT line MATCHES "^  ")
    set(suite "${line}")
    continue()
  endif()
  string(STRIP "${line}" test)
  set(full "${suite}${test}")
  if(full MATCHES "DISABLED_")
    continue()
  endif()
  if(test MATCHES "/([^/]+)$")
    set(key "${CMAKE_MATCH_1}")
    if(NOT key IN_LIST groups)
      list(APPEND groups "${key}")
      set(filter_${key} "${full}")
    else()
      string(APPEND filter_${key} ":${full}")
    endif()
  else()
    list(APPEND singles "${full}")
  endif()
endforeach()

set(out "")
foreach(name IN LISTS singles)
  string(APPEND out "add_test([=[${name}]=] [==[${TEST_EXECUTABLE}]==] [==[--gtest_filter=${name}]==])\n"
         "set_tests_properties([=[${name}]=] PROPERTIES ENVIRONMENT [==[${TEST_ENVIRONMENT}]==]"
         " SKIP_REGULAR_EXPRESSION [==[\\[  SKIPPED \\]]==])\n")
endforeach()
foreach(key IN LISTS groups)
  set(name "${executable_name}/${key}")
  string(APPEND out "add_test([=[${name}]=] [==[${TEST_EXECUTABLE}]==] [==[--gtest_filter=${filter_${key}}]==])\n"
         "set_tests_properties([=[${name}]=] PROPERTIES ENVIRONMENT [==[${TEST_ENVIRONMENT}]==])\n")
endforeach()
file(WRITE "${TEST_FILE}" "${out}")
