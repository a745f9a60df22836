# Install-time step (packaging/CMakeLists.txt): writes share/raytime/configs/demo.yaml with the
# installed sample's absolute path and a work directory in the user's home, so the installed demo
# runs from any folder without --set. A change to configs/demo.yaml that these replacements no
# longer match stops the install rather than installing a demo that cannot find its data.
file(READ "${raytime_demo_source}" demo)
set(prefix "${CMAKE_INSTALL_PREFIX}")
foreach(replacement
        "root: data/sample/fountain-P11|root: ${prefix}/${raytime_data_dir}/data/sample/fountain-P11"
        "workdir: work/demo|workdir: ~/raytime-demo"
        "# Paths are relative to the directory raytime is started from (the repository root here).|# This installed copy names the installed sample and works in ~/raytime-demo (--workdir DIR: elsewhere).")
  string(REPLACE "|" ";" pair "${replacement}")
  list(GET pair 0 from)
  list(GET pair 1 to)
  string(FIND "${demo}" "${from}" at)
  if(at EQUAL -1)
    message(FATAL_ERROR "${raytime_demo_source}: '${from}' not found; update install_demo.cmake")
  endif()
  string(REPLACE "${from}" "${to}" demo "${demo}")
endforeach()
set(destination "$ENV{DESTDIR}${prefix}/${raytime_data_dir}/configs/demo.yaml")
message(STATUS "Installing: ${destination} (the sample's installed path)")
file(WRITE "${destination}" "${demo}")
