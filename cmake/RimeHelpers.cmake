# Small helpers so every library and test is declared the same way.

# Compile options shared by all Rime targets.
function(rime_target_defaults target)
  target_compile_options(${target} PRIVATE
    $<$<COMPILE_LANGUAGE:CXX>:-Wall -Wextra -Wno-unused-parameter>
    $<$<AND:$<COMPILE_LANGUAGE:CXX>,$<BOOL:${RIME_ARCH}>>:-march=${RIME_ARCH}>
    $<$<COMPILE_LANGUAGE:CUDA>:--expt-relaxed-constexpr --extended-lambda -Xcudafe --diag_suppress=20012>)
endfunction()

# Per-test limit in seconds; the sanitizer preset raises it, since its builds run an order of
# magnitude slower (program tests' own TIMEOUTs scale with it).
set(RIME_TEST_TIMEOUT 900 CACHE STRING "CTest TIMEOUT of each GoogleTest case")

# Every test's TMPDIR: one folder of the build tree, so that temporary files stay out of the
# shared /tmp and a fixture can check that no test left any (tests/support/test_tmpdir.cmake).
set(RIME_TEST_TMPDIR ${PROJECT_BINARY_DIR}/test-tmp)
set(RIME_TEST_TMPDIR_PROPERTIES ENVIRONMENT_MODIFICATION TMPDIR=set:${RIME_TEST_TMPDIR} FIXTURES_REQUIRED rime_test_tmpdir)

# Every test carries exactly one of these labels: `unit` (fast and self-contained: the inner loop,
# `ctest -L unit`), `slow` (long simulations, real multi-stage bakes, a local cluster) or
# `validation` (figures against analytic or measured references). docs/design.md ("Tests") describes them.
set(RIME_TEST_KINDS unit slow validation)

function(rime_require_test_kind caller kind)
  if(NOT kind IN_LIST RIME_TEST_KINDS)
    message(FATAL_ERROR "${caller}: KIND must be one of ${RIME_TEST_KINDS} (got '${kind}')")
  endif()
endfunction()

# rime_add_test(NAME SOURCES ... LIBS ... KIND unit|slow|validation [SLOW test ...] [LABELS ...]
#               [PROPERTIES ...]): one GoogleTest executable registered with CTest. KIND labels
# each of its tests; SLOW names tests (Suite.Name) of a `unit` executable that are `slow` instead;
# LABELS are extra labels (e.g. farm); PROPERTIES (single-valued, e.g. RESOURCE_LOCK) apply to each.
function(rime_add_test name)
  if(NOT RIME_BUILD_TESTS)
    return()
  endif()
  cmake_parse_arguments(ARG "" "KIND" "SOURCES;LIBS;SLOW;LABELS;PROPERTIES" ${ARGN})
  rime_require_test_kind("rime_add_test(${name})" "${ARG_KIND}")
  if(ARG_SLOW AND NOT ARG_KIND STREQUAL "unit")
    message(FATAL_ERROR "rime_add_test(${name}): SLOW only moves tests of a unit executable")
  endif()
  add_executable(${name} ${ARG_SOURCES})
  target_link_libraries(${name} PRIVATE ${ARG_LIBS} rime_test_support GTest::gtest GTest::gtest_main)
  target_compile_definitions(${name} PRIVATE
    RIME_SOURCE_DIR="${PROJECT_SOURCE_DIR}"
    RIME_SHARED_DIR="${PROJECT_SOURCE_DIR}/../shared"
    RIME_BINARY_DIR="${PROJECT_BINARY_DIR}")
  rime_target_defaults(${name})
  gtest_discover_tests(${name} DISCOVERY_TIMEOUT 60 TEST_LIST ${name}_TESTS
                       PROPERTIES TIMEOUT ${RIME_TEST_TIMEOUT} ${RIME_TEST_TMPDIR_PROPERTIES} ${ARG_PROPERTIES})
  # gtest_discover_tests flattens list-valued properties; set the labels once the tests are known.
  # CTest appends labels, so each test is labelled once. CTest reads this file without policies
  # (no if(IN_LIST)); the list is undefined when the executable was not built. A SLOW name that no
  # longer matches a test stops ctest, so a renamed test cannot quietly turn unit.
  set(labels_file ${CMAKE_CURRENT_BINARY_DIR}/${name}_labels.cmake)
  set(labels ${ARG_KIND} ${ARG_LABELS})
  set(slow_labels slow ${ARG_LABELS})
  set(script "if(DEFINED ${name}_TESTS)\n  set(kind_tests \${${name}_TESTS})\n")
  foreach(test ${ARG_SLOW})
    string(APPEND script
      "  list(FIND ${name}_TESTS \"${test}\" found)\n"
      "  if(found EQUAL -1)\n"
      "    message(FATAL_ERROR \"${name}: SLOW names ${test}, which is not one of its tests (renamed?)\")\n"
      "  endif()\n"
      "  list(REMOVE_ITEM kind_tests \"${test}\")\n"
      "  set_tests_properties(\"${test}\" PROPERTIES LABELS \"${slow_labels}\")\n")
  endforeach()
  string(APPEND script "  if(kind_tests)\n    set_tests_properties(\${kind_tests} PROPERTIES LABELS \"${labels}\")\n  endif()\nendif()\n")
  file(WRITE ${labels_file} "${script}")
  set_property(DIRECTORY APPEND PROPERTY TEST_INCLUDE_FILES ${labels_file})
endfunction()

# rime_add_program_test(NAME KIND unit|slow|validation COMMAND ... [TIMEOUT s] [LABELS ...]): a test
# that runs a program which is not a GoogleTest executable (its exit code decides), labelled alike.
function(rime_add_program_test name)
  if(NOT RIME_BUILD_TESTS)
    return()
  endif()
  cmake_parse_arguments(ARG "" "KIND;TIMEOUT" "COMMAND;LABELS" ${ARGN})
  rime_require_test_kind("rime_add_program_test(${name})" "${ARG_KIND}")
  # TIMEOUT is for the release build; a raised RIME_TEST_TIMEOUT (the sanitizer preset) scales it.
  if(NOT ARG_TIMEOUT)
    set(ARG_TIMEOUT 900)
  endif()
  math(EXPR ARG_TIMEOUT "${ARG_TIMEOUT} * ${RIME_TEST_TIMEOUT} / 900")
  set(labels ${ARG_KIND} ${ARG_LABELS})
  add_test(NAME ${name} COMMAND ${ARG_COMMAND})
  set_tests_properties(${name} PROPERTIES TIMEOUT ${ARG_TIMEOUT} LABELS "${labels}" ${RIME_TEST_TMPDIR_PROPERTIES})
endfunction()

# rime_add_benchmark(STAGE SOURCES ... LIBS ...): the benchmark program rime-bench-<STAGE>, built
# with the benchmarks. RIME_BENCH_OUTPUT_DIR (its folder in the build tree) is where it writes its
# results unless told otherwise, so a run never dirties the source tree; RIME_SOURCE_DIR lets it
# record the commit it measured (rime/test/measure.h).
function(rime_add_benchmark stage)
  cmake_parse_arguments(ARG "" "" "SOURCES;LIBS" ${ARGN})
  set(name rime-bench-${stage})
  add_executable(${name} ${ARG_SOURCES})
  target_link_libraries(${name} PRIVATE ${ARG_LIBS} rime_test_support)
  target_compile_definitions(${name} PRIVATE RIME_BENCH_OUTPUT_DIR="${CMAKE_CURRENT_BINARY_DIR}"
                                             RIME_SOURCE_DIR="${PROJECT_SOURCE_DIR}")
  rime_target_defaults(${name})
endfunction()

# rime_vectorised_lanes(TARGET SOURCE ...): TARGET's C++ gets sqrt without errno and compares that may
# not trap (no IEEE arithmetic relaxed), without which GCC leaves x86-64-v3 lane loops scalar; in GCC
# Release builds the unit test Vectorised.<file> fails when a loop after RIME_IVDEP in a SOURCE does.
function(rime_vectorised_lanes target)
  target_compile_options(${target} PRIVATE $<$<COMPILE_LANGUAGE:CXX>:-fno-math-errno -fno-trapping-math>)
  if(NOT RIME_BUILD_TESTS OR NOT CMAKE_CXX_COMPILER_ID STREQUAL "GNU" OR NOT CMAKE_BUILD_TYPE STREQUAL "Release")
    return()
  endif()
  set(folder ${PROJECT_BINARY_DIR}/vectorised)
  file(MAKE_DIRECTORY ${folder})
  foreach(source ${ARGN})
    get_filename_component(path ${source} ABSOLUTE)
    get_filename_component(stem ${source} NAME_WE)
    set(report ${folder}/${stem}.txt)
    set_property(SOURCE ${source} APPEND PROPERTY COMPILE_OPTIONS -fopt-info-vec-optimized=${report})
    rime_add_program_test(Vectorised.${stem} KIND unit TIMEOUT 60
                          COMMAND ${CMAKE_COMMAND} -DSOURCE=${path} -DREPORT=${report} -P ${PROJECT_SOURCE_DIR}/cmake/check_vectorised.cmake)
  endforeach()
endfunction()
