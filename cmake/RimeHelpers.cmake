# Small helpers so every library and test is declared the same way.

# Compile options shared by all Rime targets.
function(rime_target_defaults target)
  target_compile_options(${target} PRIVATE
    $<$<COMPILE_LANGUAGE:CXX>:-Wall -Wextra -Wno-unused-parameter>
    $<$<AND:$<COMPILE_LANGUAGE:CXX>,$<BOOL:${RIME_NATIVE}>>:-march=native>
    $<$<COMPILE_LANGUAGE:CUDA>:--expt-relaxed-constexpr --extended-lambda -Xcudafe --diag_suppress=20012>)
endfunction()

# Per-test limit in seconds; the sanitizer preset raises it, since its builds run an order of
# magnitude slower.
set(RIME_TEST_TIMEOUT 900 CACHE STRING "CTest TIMEOUT of each GoogleTest case")

# rime_add_test(NAME SOURCES ... LIBS ... [LABELS ...] [PROPERTIES ...]): one GoogleTest executable
# registered with CTest; LABELS and PROPERTIES (single-valued, e.g. RESOURCE_LOCK) apply to each test.
function(rime_add_test name)
  if(NOT RIME_BUILD_TESTS)
    return()
  endif()
  cmake_parse_arguments(ARG "" "" "SOURCES;LIBS;LABELS;PROPERTIES" ${ARGN})
  add_executable(${name} ${ARG_SOURCES})
  target_link_libraries(${name} PRIVATE ${ARG_LIBS} GTest::gtest GTest::gtest_main)
  target_compile_definitions(${name} PRIVATE
    RIME_SOURCE_DIR="${PROJECT_SOURCE_DIR}"
    RIME_SHARED_DIR="${PROJECT_SOURCE_DIR}/../shared"
    RIME_BINARY_DIR="${PROJECT_BINARY_DIR}")
  rime_target_defaults(${name})
  gtest_discover_tests(${name} DISCOVERY_TIMEOUT 60 TEST_LIST ${name}_TESTS PROPERTIES TIMEOUT ${RIME_TEST_TIMEOUT} ${ARG_PROPERTIES})
  if(ARG_LABELS)
    # gtest_discover_tests flattens list-valued properties; set the labels once the tests are known.
    set(labels_file ${CMAKE_CURRENT_BINARY_DIR}/${name}_labels.cmake)
    file(WRITE ${labels_file} "set_tests_properties(\${${name}_TESTS} PROPERTIES LABELS \"${ARG_LABELS}\")\n")
    set_property(DIRECTORY APPEND PROPERTY TEST_INCLUDE_FILES ${labels_file})
  endif()
endfunction()
