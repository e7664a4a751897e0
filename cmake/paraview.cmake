# The ParaView reader plugin (src/paraview/vnr_reader.py): a Python plugin over the `vnr` module, so it
# needs VNR_PYTHON; pvpython (Debian's paraview / python3-paraview) runs its test. Nothing is compiled.
find_program(VNR_PVPYTHON_EXECUTABLE pvpython)
if(VNR_PYTHON AND VNR_PVPYTHON_EXECUTABLE)
  set(vnr_paraview_default ON)
else()
  set(vnr_paraview_default OFF)
endif()
option(VNR_PARAVIEW "Install the ParaView reader plugin for .vnr models (needs VNR_PYTHON; tested with pvpython)"
       ${vnr_paraview_default})
if(VNR_PARAVIEW AND NOT VNR_PYTHON)
  message(FATAL_ERROR "VNR_PARAVIEW needs VNR_PYTHON: the plugin reads models through the vnr Python module")
endif()

if(VNR_PARAVIEW)
  # The plugin, and a loader script for `paraview --script=` that knows where it was installed (written
  # at install time, so `cmake --install --prefix P` bakes in P).
  set(vnr_paraview_dir ${CMAKE_INSTALL_DATADIR}/vnr/paraview)
  install(FILES src/paraview/vnr_reader.py DESTINATION ${vnr_paraview_dir})
  install(CODE "
    set(VNR_PARAVIEW_INSTALL_FULL_DIR \"\${CMAKE_INSTALL_PREFIX}/${vnr_paraview_dir}\")
    message(STATUS \"Installing: \$ENV{DESTDIR}\${VNR_PARAVIEW_INSTALL_FULL_DIR}/load_vnr_reader.py\")
    configure_file(\"${CMAKE_CURRENT_SOURCE_DIR}/src/paraview/load_vnr_reader.py.in\"
                   \"\$ENV{DESTDIR}\${VNR_PARAVIEW_INSTALL_FULL_DIR}/load_vnr_reader.py\" @ONLY)")
endif()

if(VNR_BUILD_TESTS AND VNR_PYTHON)
  if(VNR_PARAVIEW AND VNR_PVPYTHON_EXECUTABLE)
    add_test(NAME paraview_reader
             COMMAND ${VNR_PVPYTHON_EXECUTABLE} ${CMAKE_CURRENT_SOURCE_DIR}/tests/paraview/test_reader.py)
    set(vnr_paraview_env VNR_CLI=$<TARGET_FILE:vnr_cli> PYTHONPATH=${CMAKE_BINARY_DIR}/python
        VNR_PVPYTHON=${VNR_PVPYTHON_EXECUTABLE}
        VNR_PARAVIEW_PLUGIN=${CMAKE_CURRENT_SOURCE_DIR}/src/paraview/vnr_reader.py)
    set_tests_properties(paraview_reader PROPERTIES ENVIRONMENT "${vnr_paraview_env}" LABELS cpu TIMEOUT 300)
  elseif(NOT VNR_PVPYTHON_EXECUTABLE)
    # Shown as "Skipped" by ctest, so a machine without ParaView does not silently lose the test.
    message(STATUS "pvpython not found: the ParaView reader test (paraview_reader) will be skipped")
    add_test(NAME paraview_reader
             COMMAND sh -c "echo 'SKIPPED: pvpython not found (install paraview python3-paraview)'; exit 77")
    set_tests_properties(paraview_reader PROPERTIES SKIP_RETURN_CODE 77 LABELS cpu)
  endif()
endif()
