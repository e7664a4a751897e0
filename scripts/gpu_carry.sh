#!/bin/sh
# Build here, run there: builds vnr for Hopper (sm_90) on this machine (nvcc needs no GPU) and packs what
# a GPU machine that reaches no package registry needs, in folders of the repo that git ignores (listed in
# .git/info/exclude) so the device tool can carry them (64 MiB in all):
#   .gpu/bin      vnr and the gpu test executables, stripped and gzipped (bench/gpu.sh unpacks them)
#   .gpu/lib      their runtime libraries that are not part of glibc, libstdc++ or the CUDA toolkit
#   .gpu/a        the position-independent static libraries (gzipped), and .gpu/include the headers of fmt,
#                 nlohmann-json and Highway: bench/gpu_python.sh links the Python module there
#   .data         the real volumes of the benchmarks (NAMES, default bonsai; SHARED/data), the raw files
#                 gzipped (bench/gpu.sh unpacks them): the four of the rd stage take 13 MiB, not 36
#   .peers        the PyTorch reference trainer (SHARED/peers)
# Then, on the GPU machine: sh bench/gpu.sh OUT (it finds .gpu, .data and .peers by itself).
#
#   sh scripts/gpu_carry.sh [SHARED]      (SHARED defaults to ../shared; NAMES="bonsai engine" for more;
#                                          NAMES="bonsai chris_t1 wmag91 engine" for the rd stage: 38 MiB in all)
# BEFORE_VNR=FILE also carries an earlier build's vnr for sm_90 (as packed here, gzipped or not) as
# .gpu/bin/vnr_before: bench/gpu.sh's `before` stage times it side by side with this one (3.4 MiB).
set -eu
# BEFORE_VNR as the caller named it, before the cd below
case ${BEFORE_VNR:-} in "" | /*) ;; *) BEFORE_VNR="$(pwd)/$BEFORE_VNR" ;; esac
cd "$(dirname "$0")/.."
SHARED=${1:-../shared}
NAMES=${NAMES:-bonsai}
B=build-gpu
ex=$(git rev-parse --git-path info/exclude)
mkdir -p "$(dirname "$ex")"
for d in .gpu .data .peers $B; do
  grep -qx "/$d/" "$ex" 2>/dev/null || echo "/$d/" >> "$ex"
done

LAUNCHER=""
command -v ccache > /dev/null 2>&1 && LAUNCHER="-DCMAKE_CXX_COMPILER_LAUNCHER=ccache -DCMAKE_CUDA_COMPILER_LAUNCHER=ccache"
# shellcheck disable=SC2086
cmake -S . -B $B -G Ninja -DCMAKE_BUILD_TYPE=Release -DVNR_CUDA=ON -DCMAKE_CUDA_ARCHITECTURES=90 \
  -DVNR_BUILD_BENCH=OFF -DVNR_PYTHON=OFF -DVNR_MPI=OFF -DVNR_HDF5=OFF -DVNR_NETCDF=OFF \
  -DCMAKE_POSITION_INDEPENDENT_CODE=ON -DCMAKE_CXX_FLAGS=-fno-semantic-interposition $LAUNCHER > /dev/null
# shellcheck disable=SC2046
cmake --build $B -j "$(nproc)" --target vnr_cli $(for f in tests/test_gpu*.cpp; do basename "$f" .cpp; done)

rm -rf .gpu
mkdir -p .gpu/bin .gpu/lib .gpu/a .gpu/include
for t in vnr $B/test_gpu*; do
  t=$(basename "$t")
  case $t in *.cmake | *_tests.cmake) continue ;; esac
  [ -x "$B/$t" ] || continue
  strip -o ".gpu/bin/$t" "$B/$t"
done
# Libraries from Debian's packages; glibc, libstdc++, libgcc and CUDA's own come from the GPU image.
for bin in .gpu/bin/*; do
  ldd "$bin" | awk '/=> \// { print $3 }'
done | sort -u | while read -r lib; do
  case $(basename "$lib") in
    libc.so* | libm.so* | libstdc++* | libgcc_s* | ld-linux* | libdl.so* | libpthread* | librt.so* | libcublas*) ;;
    *) cp -L "$lib" .gpu/lib/ ;;
  esac
done
cp -L /usr/lib/x86_64-linux-gnu/libzfp.so.1 .gpu/lib/ 2>/dev/null || true
cp $B/libvnr_*.a .gpu/a/
rm -f .gpu/a/libvnr_view.a
for h in fmt nlohmann hwy; do cp -r "/usr/include/$h" .gpu/include/; done
git rev-parse --short HEAD > .gpu/commit
git diff --quiet HEAD || echo "(with uncommitted changes)" >> .gpu/commit

rm -rf .data .peers
mkdir -p .data .peers
for name in $NAMES; do
  if [ -f "$SHARED/data/$name.json" ]; then
    cp "$SHARED/data/$name.json" .data/
    cp "$SHARED/data/$name"_*.raw .data/
  fi
done
for raw in .data/*.raw; do [ -f "$raw" ] && chmod u+w "$raw" && gzip -6 "$raw"; done
[ -f "$SHARED/peers/torch_vnr.py" ] && cp "$SHARED/peers/torch_vnr.py" .peers/
# gzipped, as the volumes (bench/gpu.sh unpacks both): the binaries each link the whole library and its
# kernels, 37 MiB unpacked, and the carry holds 64 MiB
gzip -6 .gpu/bin/* .gpu/a/*
if [ -n "${BEFORE_VNR:-}" ]; then
  case $BEFORE_VNR in
    *.gz) cp "$BEFORE_VNR" .gpu/bin/vnr_before.gz ;;
    *) gzip -6 -c "$BEFORE_VNR" > .gpu/bin/vnr_before.gz ;;
  esac
  basename "$BEFORE_VNR" > .gpu/before
fi
du -sh .gpu/bin .gpu/lib .gpu/a .gpu/include .data .peers
total=$(du -sm .gpu .data .peers | awk '{ s += $1 } END { print s }')
echo "the carry: $total MiB of 64"
[ "$total" -le 64 ] || echo "more than the device tool carries: fewer NAMES, or leave .gpu/a and .gpu/include (the python stage) out"
