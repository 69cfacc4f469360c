#!/usr/bin/env bash
# The toolkit without its optional parts (issue 12): configures build-minimal/ with -DHC_WITH_GL=OFF,
# -DHC_WITH_VDB=OFF and -DHC_WITH_MPI=OFF, checks that no program there links OpenGL, EGL, GLFW, OpenVDB or MPI (and that
# the full build's command-line tools other than hc-render, hc-view and hc-bench link no GL either), and runs the whole
# suite there: the CPU tools work, --backend gl / .vdb say they were built out, and mpirun with several ranks is refused.
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/deps.sh
bash scripts/build.sh build-minimal -DHC_WITH_GL=OFF -DHC_WITH_VDB=OFF -DHC_WITH_MPI=OFF

optional='lib(OpenGL|GL|GLX|EGL|GLdispatch|glfw|openvdb|mpi|mpi_cxx)\.so'
status=0
links() { { ldd "$1" | grep -oE "$optional[^ ]*" || true; } | sort -u | tr '\n' ' '; }
[ -e build-minimal/bin/hc-view ] && { echo "test_minimal: hc-view exists in a build with HC_WITH_GL=OFF" >&2; status=1; }
for exe in build-minimal/bin/* build-minimal/tests/*_test; do
  found=$(links "$exe")
  if [ -n "$found" ]; then echo "test_minimal: $exe links $found" >&2; status=1; fi
done
# In the full build only the programs that render (hc-render, hc-bench, hc-view) may link GL, only hc-export OpenVDB.
if [ -d build/bin ]; then
  for tool in hc-ingest hc-info hc-influence hc-probe hc-export hc-bench-ingest hc-bench-influence hc-bench-parallel; do
    [ -e "build/bin/$tool" ] || continue
    found=$(links "build/bin/$tool" | grep -oE 'lib(OpenGL|GL|GLX|EGL|GLdispatch|glfw)[^ ]*' || true)
    if [ -n "$found" ]; then echo "test_minimal: build/bin/$tool links $found" >&2; status=1; fi
  done
fi
[ $status -eq 0 ] || exit 1
echo "test_minimal: no program of build-minimal/ links OpenGL, EGL, GLFW, OpenVDB or MPI"
ctest --test-dir build-minimal -j"$(nproc)" --output-on-failure
