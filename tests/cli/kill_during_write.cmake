# kill -9 during every write (issue 11): each writer is SIGKILLed at points spread over its run and as soon as
# its temporary appears; its outputs must then be absent or complete and valid, anything else left must be a
# temporary (OUTPUT.tmp.XXXXXX), and the next run removes those. kill_during_write.sh says how and why.
set(writers ingest influence info_csv probe_csv render export_tif export_exr)
set(HC_VDB_CHECK "")
if(HC_WITH_VDB)
  add_executable(hc_vdb_check vdb_check.cpp)
  target_link_libraries(hc_vdb_check PRIVATE OpenVDB::openvdb)
  hc_target_defaults(hc_vdb_check)
  list(APPEND writers export_vdb)
  set(HC_VDB_CHECK $<TARGET_FILE:hc_vdb_check>)
endif()

foreach(writer ${writers})
  add_test(NAME cli.kill.${writer} COMMAND ${HC_BASH} ${CMAKE_CURRENT_SOURCE_DIR}/kill_during_write.sh ${writer})
  set_tests_properties(cli.kill.${writer} PROPERTIES LABELS cli TIMEOUT 600
    ENVIRONMENT "HC_INGEST=${INGEST};HC_INFO=${INFO};HC_INFLUENCE=${INFLUENCE};HC_PROBE=${PROBE};HC_RENDER=${RENDER};HC_EXPORT=${EXPORT};HC_FILE_CHECK=${HC_VDB_CHECK};HC_DATA_DIR=${HC_DATA_DIR};HC_CLI_WORK=${HC_CLI_WORK};LC_ALL=C")
endforeach()

# The sanitizer build (scripts/test_sanitized.sh): hc-view's tests open a GL window under Xvfb, where
# LeakSanitizer fails them on allocations inside Mesa and the X libraries (unsymbolised frames of the run-time
# loaded driver, none in our code; docs/testing.md saw it crash in llvmpipe too), so they run without it;
# every other CLI test keeps leak detection. Set here because this file is included last, after every cli.view.* test exists.
get_property(hc_cli_tests DIRECTORY PROPERTY TESTS)
foreach(t IN LISTS hc_cli_tests)
  if(t MATCHES "^cli\\.view\\.")
    set_property(TEST ${t} APPEND PROPERTY ENVIRONMENT ASAN_OPTIONS=detect_leaks=0)
  endif()
endforeach()
