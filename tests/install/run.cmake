# ctest install_and_consume: cmake --install into a fresh prefix, check the layout, then configure,
# build and run tests/install (find_package(vnr), vnr::vnr) against that prefix.
set(prefix ${VNR_WORK_DIR}/prefix)
file(REMOVE_RECURSE ${VNR_WORK_DIR})
function(run_step)
  execute_process(COMMAND ${ARGN} RESULT_VARIABLE rc OUTPUT_VARIABLE out ERROR_VARIABLE err)
  if(NOT rc EQUAL 0)
    message(FATAL_ERROR "failed (${rc}): ${ARGN}\n${out}\n${err}")
  endif()
endfunction()
run_step(${CMAKE_COMMAND} --install ${VNR_BUILD_DIR} --prefix ${prefix})
foreach(f bin/vnr share/vnr/plot_rd.py share/vnr/peers_rd.json include/vnr/vnr.h include/vnr/renderer.h include/vnr/volume/volume.h include/vnr/render/renderer.h
          lib/cmake/vnr/vnrConfig.cmake lib/cmake/vnr/vnrTargets.cmake)
  if(NOT EXISTS ${prefix}/${f} AND NOT EXISTS ${prefix}/lib64/${f})
    message(FATAL_ERROR "not installed: ${prefix}/${f}")
  endif()
endforeach()
set(launcher "")
if(VNR_CXX_LAUNCHER)
  set(launcher -DCMAKE_CXX_COMPILER_LAUNCHER=${VNR_CXX_LAUNCHER})
endif()
run_step(${CMAKE_COMMAND} -S ${VNR_CONSUMER_DIR} -B ${VNR_WORK_DIR}/build -G Ninja -DCMAKE_BUILD_TYPE=Release
         -DCMAKE_CXX_COMPILER=${VNR_CXX_COMPILER} ${launcher} -DCMAKE_PREFIX_PATH=${prefix})
run_step(${CMAKE_COMMAND} --build ${VNR_WORK_DIR}/build)
run_step(${VNR_WORK_DIR}/build/consumer)
run_step(${prefix}/bin/vnr --version)
# `vnr bench rd --plot` finds its script under <prefix>/share/vnr (Debian's python3-matplotlib draws it).
execute_process(COMMAND /usr/bin/python3 -c "import matplotlib" RESULT_VARIABLE no_matplotlib OUTPUT_QUIET ERROR_QUIET)
if(no_matplotlib EQUAL 0)
  run_step(${prefix}/bin/vnr synth marschner-lobb --dims 24,24,24 -o ${VNR_WORK_DIR}/ml.json)
  run_step(${prefix}/bin/vnr bench rd ${VNR_WORK_DIR}/ml.json --config small --steps 5 --ratios 4,1024 --bounds 1e-2
           --zfp-rates 2 --threads 1 --device cpu --report ${VNR_WORK_DIR}/rd.json --plot ${VNR_WORK_DIR}/rd.png
           --peers ${prefix}/share/vnr/peers_rd.json)
  file(READ ${VNR_WORK_DIR}/rd.png png_head LIMIT 4 HEX)
  if(NOT png_head STREQUAL "89504e47")
    message(FATAL_ERROR "vnr bench rd --plot did not write a PNG (${png_head})")
  endif()
endif()
file(REMOVE_RECURSE ${VNR_WORK_DIR})
