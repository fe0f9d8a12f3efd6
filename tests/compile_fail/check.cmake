# Compiles SOURCE with the C++ compiler; passes when the outcome matches EXPECT:
#   EXPECT=success           -> must compile
#   EXPECT=<text>            -> must fail, and the diagnostics must contain <text>
execute_process(COMMAND ${COMPILER} -std=c++17 -fsyntax-only -I${INCLUDE_DIR} ${SOURCE}
                RESULT_VARIABLE result OUTPUT_VARIABLE out ERROR_VARIABLE err)
if(EXPECT STREQUAL "success")
  if(NOT result EQUAL 0)
    message(FATAL_ERROR "${SOURCE} should compile but did not:\n${err}")
  endif()
else()
  if(result EQUAL 0)
    message(FATAL_ERROR "${SOURCE} compiled, but the contract check should have rejected it")
  endif()
  string(FIND "${err}" "${EXPECT}" where)
  if(where EQUAL -1)
    message(FATAL_ERROR "${SOURCE} failed without the expected message '${EXPECT}':\n${err}")
  endif()
  message(STATUS "rejected as expected: ${EXPECT}")
endif()
