# Install-time step (packaging/CMakeLists.txt): writes share/raytime/configs/demo.yaml with the
# installed sample's absolute path and a work directory in the user's home, so the installed demo
# runs from any folder without --set. A change to configs/demo.yaml that these replacements no
# longer match stops the install rather than installing a demo that cannot find its data.
file(READ "${raytime_demo_source}" demo)
set(prefix "${CMAKE_INSTALL_PREFIX}")
set(from_1 "root: data/sample/fountain-P11")
set(to_1 "root: ${prefix}/${raytime_data_dir}/data/sample/fountain-P11")
set(from_2 "workdir: work/demo")
set(to_2 "workdir: ~/raytime-demo")
string(CONCAT from_3 "# Paths are relative to the directory raytime is started from "
       "(the repository root here).")
set(to_3 "# This installed copy reads the installed sample and works in ~/raytime-demo.")
foreach(i 1 2 3)
  string(FIND "${demo}" "${from_${i}}" at)
  if(at EQUAL -1)
    message(FATAL_ERROR
            "${raytime_demo_source}: '${from_${i}}' not found; update install_demo.cmake")
  endif()
  string(REPLACE "${from_${i}}" "${to_${i}}" demo "${demo}")
endforeach()
set(destination "$ENV{DESTDIR}${prefix}/${raytime_data_dir}/configs/demo.yaml")
message(STATUS "Installing: ${destination} (the sample's installed path)")
file(WRITE "${destination}" "${demo}")
