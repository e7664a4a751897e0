# The layering of docs/ARCHITECTURE.md, checked on the sources: every `#include "vnr/<layer>/..."` in
# src/vnr/<layer>/ names the layer itself or one it may use. (The link graph checks symbols; this checks
# header-only includes too.)  cmake -DVNR_SOURCE_DIR=... -P tests/layering.cmake
cmake_policy(SET CMP0057 NEW)
set(allowed_core core)
set(allowed_volume core volume)
set(allowed_nn core nn)
set(allowed_cuda core volume nn cuda)
set(allowed_train core volume nn cuda train)
set(allowed_render core render)
set(allowed_render_cuda core render cuda render_cuda)
set(allowed_fields core volume nn cuda render render_cuda fields)
set(allowed_online core volume nn cuda train render render_cuda fields online)
set(allowed_api core volume nn cuda train render render_cuda fields online api)
set(violations "")
foreach(layer core volume nn cuda train render render_cuda fields online api)
  file(GLOB_RECURSE files ${VNR_SOURCE_DIR}/src/vnr/${layer}/*.h ${VNR_SOURCE_DIR}/src/vnr/${layer}/*.cpp
       ${VNR_SOURCE_DIR}/src/vnr/${layer}/*.cu ${VNR_SOURCE_DIR}/src/vnr/${layer}/*.cuh)
  foreach(f ${files})
    file(STRINGS ${f} includes REGEX "^#include \"vnr/[a-z_]+/")
    foreach(line ${includes})
      string(REGEX REPLACE "^#include \"vnr/([a-z_]+)/.*" "\\1" used "${line}")
      if(NOT used IN_LIST allowed_${layer})
        file(RELATIVE_PATH rel ${VNR_SOURCE_DIR} ${f})
        list(APPEND violations "${rel}: layer '${layer}' includes '${used}'")
      endif()
    endforeach()
  endforeach()
endforeach()
# Front ends reach the library through include/vnr; the internal headers each still includes (issue 40
# moves them behind the public API) are listed here, and this list only shrinks: a new one fails.
set(frontend_cli cuda/cuda.h nn/config.h nn/mlp_kernels.h nn/network.h online/preview.h
    render/renderer.h render/transfer_function.h train/bricks.h train/make_trainer.h train/model_io.h
    train/psnr_search.h train/series.h train/session.h train/training_data.h volume/dataset.h
    volume/raw_access.h volume/stream.h volume/writer.h)
set(frontend_python core/metrics.h core/parallel.h train/bricks.h train/psnr_search.h volume/sample_io.h
    volume/writer.h)
set(frontend_view render/image.h)
set(frontend_mpi render/image.h)
set(frontend_paraview "")
foreach(frontend cli python view mpi paraview)
  file(GLOB_RECURSE files ${VNR_SOURCE_DIR}/src/${frontend}/*.h ${VNR_SOURCE_DIR}/src/${frontend}/*.cpp
       ${VNR_SOURCE_DIR}/src/${frontend}/*.cu)
  foreach(f ${files})
    file(STRINGS ${f} includes REGEX "^#include \"vnr/[a-z_]+/")
    foreach(line ${includes})
      string(REGEX REPLACE "^#include \"vnr/([a-z_]+/[^\"]+)\".*" "\\1" used "${line}")
      if(NOT used IN_LIST frontend_${frontend})
        file(RELATIVE_PATH rel ${VNR_SOURCE_DIR} ${f})
        list(APPEND violations "${rel}: front end '${frontend}' includes the internal 'vnr/${used}' (use include/vnr)")
      endif()
    endforeach()
  endforeach()
endforeach()
if(violations)
  list(JOIN violations "\n" text)
  message(FATAL_ERROR "layering violations:\n${text}")
endif()
message(STATUS "layering: every include of src/vnr follows docs/ARCHITECTURE.md; front ends include no new internal header")
