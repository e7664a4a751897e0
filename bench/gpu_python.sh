#!/bin/sh
# The Python module's device="cuda" tests on a GPU machine whose python3 is not the one this project
# builds for (the GPU images carry their own Python with numpy): compiles src/python there against the
# prebuilt position-independent static libraries of .gpu/a (scripts/gpu_carry.sh) and pybind11 from that
# python's packages, then runs tests/python/test_cuda.py. Logs to OUT/python_*.log.
#
#   sh bench/gpu_python.sh OUT      (bench/gpu.sh runs it as its `python` stage)
set -u
OUT=$1
if [ ! -d .gpu/a ]; then echo "python: no .gpu/a (run scripts/gpu_carry.sh); skipped"; exit 0; fi
PYINC=$(python3 -m pybind11 --includes 2>/dev/null) || { echo "python: pybind11 missing there; skipped"; exit 0; }
EXT=$(python3 -c "import sysconfig; print(sysconfig.get_config_var('EXT_SUFFIX'))")
D=/tmp/vnr-python
mkdir -p "$D/vnr"
cp src/python/vnr/* "$D/vnr/"
objs=""
for f in src/python/*.cpp; do
  o="$D/$(basename "$f" .cpp).o"
  objs="$objs $o"
  # shellcheck disable=SC2086
  g++ -std=c++20 -O2 -fPIC -fvisibility=hidden -DNDEBUG -DFMT_SHARED -DHWY_SHARED_DEFINE -DVNR_VERSION="\"$(sed -n "s/^project(vnr VERSION \([0-9.]*\).*/\1/p" CMakeLists.txt)\"" $PYINC -Iinclude -Isrc \
    -I.gpu/include -c "$f" -o "$o" > "$OUT/python_compile_$(basename "$f" .cpp).log" 2>&1 &
done
wait
L=.gpu/lib
C=/usr/local/cuda/lib64
# shellcheck disable=SC2086
if ! g++ -shared -o "$D/vnr/_vnr$EXT" $objs -Wl,--start-group .gpu/a/*.a -Wl,--end-group \
  "$C/libcudart_static.a" -L"$C" -lcublas -lcublasLt "$C/libculibos.a" $L/libpng16.so.16 $L/libzfp.so.1 \
  $L/libhwy.so.1 $L/libzstd.so.1 $L/libfmt.so.9 -lz -fopenmp -ldl -lrt -lpthread > "$OUT/python_link.log" 2>&1; then
  echo "python: the module did not build:"
  cat "$OUT"/python_compile_*.log "$OUT/python_link.log" | grep -m5 -i error
  exit 1
fi
PYTHONPATH="$D" VNR_REQUIRE_CUDA=1 timeout 240 python3 -m pytest -q -s -p no:cacheprovider tests/python/test_cuda.py \
  > "$OUT/python_test_cuda.log" 2>&1
rc=$?
tail -8 "$OUT/python_test_cuda.log"
exit $rc
