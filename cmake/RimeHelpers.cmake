# Small helpers so every library and test is declared the same way.

# Compile options shared by all Rime targets.
function(rime_target_defaults target)
  target_compile_options(${target} PRIVATE
    $<$<COMPILE_LANGUAGE:CXX>:-Wall -Wextra -Wno-unused-parameter>
    $<$<AND:$<COMPILE_LANGUAGE:CXX>,$<BOOL:${RIME_NATIVE}>>:-march=native>
    $<$<COMPILE_LANGUAGE:CUDA>:--expt-relaxed-constexpr --extended-lambda -Xcudafe --diag_suppress=20012>)
endfunction()

# rime_add_test(NAME SOURCES ... LIBS ... [PROPERTIES ...]): one GoogleTest executable registered
# with CTest; PROPERTIES are extra CTest properties of its tests (e.g. LABELS, RESOURCE_LOCK).
function(rime_add_test name)
  if(NOT RIME_BUILD_TESTS)
    return()
  endif()
  cmake_parse_arguments(ARG "" "" "SOURCES;LIBS;PROPERTIES" ${ARGN})
  add_executable(${name} ${ARG_SOURCES})
  target_link_libraries(${name} PRIVATE ${ARG_LIBS} GTest::gtest GTest::gtest_main)
  target_compile_definitions(${name} PRIVATE
    RIME_SOURCE_DIR="${PROJECT_SOURCE_DIR}"
    RIME_SHARED_DIR="${PROJECT_SOURCE_DIR}/../shared"
    RIME_BINARY_DIR="${PROJECT_BINARY_DIR}")
  rime_target_defaults(${name})
  gtest_discover_tests(${name} DISCOVERY_TIMEOUT 60 PROPERTIES TIMEOUT 900 ${ARG_PROPERTIES})
endfunction()
