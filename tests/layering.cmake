# The layering of docs/ARCHITECTURE.md, checked on the sources: every `#include "vnr/<layer>/..."` in
# src/vnr/<layer>/ names the layer itself or one it may use. (The link graph checks symbols; this checks
# header-only includes too.)  cmake -DVNR_SOURCE_DIR=... -P tests/layering.cmake
cmake_policy(SET CMP0057 NEW)
cmake_policy(SET CMP0054 NEW)
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
# Every `#include "vnr/<layer>/..."` of the sources under `dir`: its layer (kind "layer") or its header
# "layer/file.h" (kind "header") must be in `allowed`; violations are appended to `violations`.
function(check_includes dir kind allowed label)
  file(GLOB_RECURSE files ${dir}/*.h ${dir}/*.cpp ${dir}/*.cu ${dir}/*.cuh)
  foreach(f ${files})
    file(STRINGS ${f} includes REGEX "^#include \"vnr/[a-z_]+/")
    foreach(line ${includes})
      if(kind STREQUAL "layer")
        string(REGEX REPLACE "^#include \"vnr/([a-z_]+)/.*" "\\1" used "${line}")
      else()
        string(REGEX REPLACE "^#include \"vnr/([a-z_]+/[^\"]+)\".*" "\\1" used "${line}")
      endif()
      if(NOT used IN_LIST allowed)
        file(RELATIVE_PATH rel ${VNR_SOURCE_DIR} ${f})
        list(APPEND violations "${rel}: ${label} includes '${used}'")
      endif()
    endforeach()
  endforeach()
  set(violations ${violations} PARENT_SCOPE)
endfunction()
set(violations "")
foreach(layer core volume nn cuda train render render_cuda fields online api)
  check_includes(${VNR_SOURCE_DIR}/src/vnr/${layer} layer "${allowed_${layer}}" "layer '${layer}'")
endforeach()
# Front ends reach the library through include/vnr; the internal headers each still includes (issue 40
# moves them behind the public API) are listed here, and this list only shrinks: a new one fails.
set(frontend_cli cuda/cuda.h nn/mlp_kernels.h nn/network.h online/preview.h train/bricks.h
    train/psnr_search.h train/session.h train/training_data.h volume/raw_access.h volume/stream.h
    volume/writer.h)
set(frontend_python core/parallel.h train/bricks.h train/psnr_search.h volume/sample_io.h
    volume/writer.h)
set(frontend_view "")
set(frontend_mpi "")
set(frontend_paraview "")
foreach(frontend cli python view mpi paraview)
  check_includes(${VNR_SOURCE_DIR}/src/${frontend} header "${frontend_${frontend}}"
                 "front end '${frontend}' (which reaches the library through include/vnr)")
endforeach()
if(violations)
  list(JOIN violations "\n" text)
  message(FATAL_ERROR "layering violations:\n${text}")
endif()
message(STATUS "layering: every include of src/vnr follows docs/ARCHITECTURE.md; front ends include no new internal header")
