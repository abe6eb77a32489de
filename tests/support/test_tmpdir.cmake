# The suite's temporary folder (RIME_TEST_TMPDIR, the TMPDIR of every test): ACTION=prepare empties
# it before the tests run, ACTION=check fails when a test left anything in it, naming what, and
# keeps it for inspection. RIME_KEEP_TEST_FILES=1 (tests keep their folders) keeps and passes both.
# One ctest run at a time per build tree: a second run's prepare would empty the first's folders.
if(NOT FOLDER OR NOT ACTION)
  message(FATAL_ERROR "usage: cmake -DFOLDER=<dir> -DACTION=prepare|check -P test_tmpdir.cmake")
endif()
set(keep OFF)
if("$ENV{RIME_KEEP_TEST_FILES}" STREQUAL "1")
  set(keep ON)
endif()

if(ACTION STREQUAL "prepare")
  if(NOT keep)
    file(REMOVE_RECURSE "${FOLDER}")
  endif()
  file(MAKE_DIRECTORY "${FOLDER}")
elseif(ACTION STREQUAL "check")
  file(GLOB left LIST_DIRECTORIES true RELATIVE "${FOLDER}" "${FOLDER}/*" "${FOLDER}/.*")
  list(LENGTH left count)
  if(count EQUAL 0)
    message(STATUS "no test left a file in ${FOLDER}")
  elseif(keep)
    message(STATUS "RIME_KEEP_TEST_FILES=1: ${count} entries kept in ${FOLDER}: ${left}")
  else()
    list(JOIN left "\n  " names)
    message(FATAL_ERROR "tests left ${count} entries in ${FOLDER} (the name says which test; "
                        "rime/test/temp_folder.h removes a folder by itself):\n  ${names}")
  endif()
else()
  message(FATAL_ERROR "ACTION must be prepare or check (got '${ACTION}')")
endif()
