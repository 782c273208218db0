#!/usr/bin/env bash
# GPU sweep report: correctness at full size and speed on a machine with a real GPU.
#
#   benches/gpu_report.sh                 build (release) here, run the GPU tests, print the table
#   benches/gpu_report.sh --stage         only build, and copy the binaries to .gpu-bin/ so they can
#                                         travel to a machine without cargo (e.g. the device tool's
#                                         `carry`), together with the Vulkan loader debs in .gl/
#   benches/gpu_report.sh --small         a quick run at small sizes (works on lavapipe: about 30 s here)
#
# On a machine without cargo the script uses the binaries in $CTSID_GPU_BIN_DIR (default
# .gpu-bin). If the Vulkan loader is missing and .gl/*.deb exist, it unpacks them first
# (see the device README); if the NVIDIA ICD file exists and no driver is set, it uses it.
# The report requires a real (non-CPU) adapter unless --small is given. Extra arguments go to
# the report binary (e.g. --samples 25000 --sizes 11:6,17:6,13:9 --reps 20).
set -euo pipefail
cd "$(dirname "$0")/.."
BIN_DIR=${CTSID_GPU_BIN_DIR:-.gpu-bin}

mode=full
if [[ "${1:-}" == "--stage" ]]; then mode=stage; shift; fi
if [[ "${1:-}" == "--small" ]]; then mode=small; shift; fi

if command -v cargo >/dev/null 2>&1; then
    # The report is a research program (benches/research/gpu_report.rs, run directly here).
    report=$(cargo bench --bench gpu_report --no-run 2>&1 \
        | sed -n 's/.*Executable benches\/research\/gpu_report.rs (\(.*\))$/\1/p' | tail -1)
    [[ -x "$report" ]] || { echo "gpu_report.sh: cannot find the gpu_report binary" >&2; exit 2; }
    # The test binary's path as cargo prints it: a bench of the same name (benches/gpu_sweep.rs,
    # a criterion harness) also builds deps/gpu_sweep-*, so the newest file is not always the test.
    gputest=$(cargo test --release --test gpu_sweep --no-run 2>&1 \
        | sed -n 's/.*Executable tests\/gpu_sweep.rs (\(.*\))$/\1/p' | tail -1)
    [[ -x "$gputest" ]] || { echo "gpu_report.sh: cannot find the gpu_sweep test binary" >&2; exit 2; }
    if [[ $mode == stage ]]; then
        mkdir -p "$BIN_DIR"
        cp "$report" "$BIN_DIR/gpu_report"
        cp "$gputest" "$BIN_DIR/gpu_sweep_test"
        # A self-ignoring folder: git never sees it, and the device tool can carry it.
        echo '*' > "$BIN_DIR/.gitignore"
        echo "staged $BIN_DIR/gpu_report and $BIN_DIR/gpu_sweep_test"
        exit 0
    fi
else
    report="$BIN_DIR/gpu_report"
    gputest="$BIN_DIR/gpu_sweep_test"
    [[ -x "$report" ]] || { echo "gpu_report.sh: no cargo and no $report; run 'benches/gpu_report.sh --stage' on a build machine" >&2; exit 2; }
fi

# Vulkan loader and driver on a bare GPU machine.
if ! ldconfig -p 2>/dev/null | grep -q libvulkan.so.1 && compgen -G ".gl/*.deb" >/dev/null; then
    for f in .gl/*.deb; do dpkg -x "$f" /; done
    ldconfig
fi
nv_icd=/usr/local/nvidia/share/vulkan/icd.d/nvidia_icd.json
if [[ -z "${VK_DRIVER_FILES:-}" && -f $nv_icd ]]; then export VK_DRIVER_FILES=$nv_icd; fi

if [[ $mode == small ]]; then
    "$report" --samples 3000 --sizes 11:3,8:5,6:7 --reps 3 --check 500 --steps 20 "$@"
    exit
fi

echo "== GPU correctness tests (CTSID_REQUIRE_GPU=1) =="
# One test at a time: on the H200 a parallel run of this binary once hung (no output for 470 s).
tests_rc=0; CTSID_REQUIRE_GPU=1 "$gputest" --test-threads 1 || tests_rc=$?
echo "== report: 25,000 samples x {12,376 (n_z=11,d=6), 100,947 (n_z=17,d=6), 497,420 (n_z=13,d=9)} =="
"$report" --require-real-gpu --samples 25000 --sizes 11:6,17:6,13:9 --reps 20 --check 2000 "$@"
exit "$tests_rc"
