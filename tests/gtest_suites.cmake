# Read by ctest (a directory's TEST_INCLUDE_FILES), not by CMake's configure step: one ctest test
# per GoogleTest suite of an executable, named "Suite.*" and running --gtest_filter=Suite.*, so
# `ctest -R Suite.` selects a suite as with one test per test. The suites are listed when ctest
# runs (as gtest_discover_tests' PRE_TEST mode): a test added to a source needs no CMake run.
#
# Why not one process per test: starting the unit-test binary costs ~0.3 s in a Release build and
# ~0.7 s under the sanitizers (the loader binds the ~250 libraries OpenCV's Debian packages pull
# in, LeakSanitizer scans the whole process at exit), so 350 one-test processes spent more than
# half of CI's sanitizer test time starting and stopping; the tests themselves take ~12 s in one
# Release process. A failing suite's output names the failing test; one test runs alone with
# `tests/raytime_unit_tests --gtest_filter=Suite.Test`.
function(raytime_add_gtest_suites executable label working_directory)
  if(NOT EXISTS "${executable}")
    add_test("${label}_tests_NOT_BUILT" "${label}_tests_NOT_BUILT")
    return()
  endif()
  execute_process(COMMAND "${executable}" --gtest_list_tests
                  WORKING_DIRECTORY "${working_directory}"
                  TIMEOUT 120
                  RESULT_VARIABLE result
                  OUTPUT_VARIABLE listing
                  ERROR_VARIABLE errors)
  if(NOT result EQUAL 0)
    add_test("${label}_tests_NOT_LISTED" "${executable}" --gtest_list_tests)
    message(WARNING "${executable} --gtest_list_tests failed (${result}): ${errors}")
    return()
  endif()
  # Parameter comments ("# GetParam() = [...]") may hold brackets and semicolons, which a CMake
  # list would not split as lines.
  string(REPLACE "[" "(" listing "${listing}")
  string(REPLACE "]" ")" listing "${listing}")
  string(REPLACE ";" "," listing "${listing}")
  string(REPLACE "\n" ";" lines "${listing}")
  set(count 0)
  foreach(line IN LISTS lines)
    # A suite's line is not indented and ends its name with a dot: "Suite.",
    # "Prefix/Suite.", "TypedSuite/0.  # TypeParam = int"; its tests' lines are indented.
    if(line MATCHES "^([^ #][^ ]*)\\.( |$)")
      set(suite "${CMAKE_MATCH_1}")
      add_test("${suite}.*" "${executable}" "--gtest_filter=${suite}.*")
      set_tests_properties("${suite}.*" PROPERTIES LABELS "${label}"
                           WORKING_DIRECTORY "${working_directory}")
      math(EXPR count "${count} + 1")
    endif()
  endforeach()
  if(count EQUAL 0)
    add_test("${label}_tests_NONE_LISTED" "${executable}" --gtest_list_tests)
    message(WARNING "${executable} --gtest_list_tests listed no suite")
  endif()
endfunction()
