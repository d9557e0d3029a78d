#!/usr/bin/env bash
# One command for a new machine or GPU: install the vkfft extra, then `clsdcam check`, the device path's kernel
# benchmark (every device FFT engine) and the iteration benchmark on one OpenCL device, everything into OUTDIR.
#
#   tools/device_report.sh OUTDIR [--device SUBSTRING] [--size HxW] [--bands K] [--repeat N] [--ranks R,..]
#                                 [--backends LIST] [--no-install] [--tests] [--demo] [--panel N] [--breakdown]
#
# The device: --device (a substring of its platform or device name, as `clsdcam --device`), else PYOPENCL_CTX, else
# the first GPU, else the first CPU (clsdcam.backends.cl_devices.choose_device); every step runs on it through
# PYOPENCL_CTX="platform:device". Intel's CPU runtime and Oclgrind are listed beside the system's drivers when
# installed (python -m clsdcam.backends.cl_icd). Defaults are the full problem (64 bands, sensor 320x448, the GPU
# target of issue 18: an iteration in <= 3 ms on one H100); on a CPU take a small one, e.g.
#   tools/device_report.sh /tmp/report --device Intel --size 32x48 --bands 8 --repeat 1 --no-install
# The iteration benchmark runs --backends: opencl by default; numpy,opencl adds NumPy's rows, which take minutes at
# full size (on the 16-core host of an H200 they had not finished after 150 s).
# Then, when asked, the checks that need a GPU (issue 47): --tests the parity and device-check tests on the device;
# --demo `clsdcam demo` as today's default (300 FISTA iterations) and as the default, one after the other (their
# folders in a scratch directory: a full-size cube is 37 MB); --panel N a fresh N-scene panel of tools/bench_converged.py
# at --size/--bands on the device (OUTDIR/panel, its references cached in the scratch directory); --breakdown where a
# solve's time goes on the device (tools/bench_breakdown.py, 300 iterations: ADMM's set-up, balance and margin
# correction among the parts).
# Python: $PYTHON, else .venv/bin/python, else python3. A failing step is recorded in summary.txt (exit code, log)
# and the next one still runs; the script's own exit code is the number of failed steps.
set -uo pipefail
cd "$(dirname "$0")/.."

usage() { sed -n '5,6p' "$0" | sed 's/^# *//' >&2; exit 2; }
[ $# -ge 1 ] && [ "${1#-}" = "$1" ] || usage
OUT=$1; shift
DEVICE="" SIZE=320x448 BANDS=64 REPEAT=3 RANKS=3,8 BACKENDS=opencl INSTALL=1 TESTS=0 DEMO=0 PANEL=0 BREAKDOWN=0
while [ $# -gt 0 ]; do
    case $1 in
        --device) DEVICE=$2; shift 2 ;;
        --size) SIZE=$2; shift 2 ;;
        --bands) BANDS=$2; shift 2 ;;
        --repeat) REPEAT=$2; shift 2 ;;
        --ranks) RANKS=$2; shift 2 ;;
        --backends) BACKENDS=$2; shift 2 ;;
        --no-install) INSTALL=0; shift ;;
        --tests) TESTS=1; shift ;;
        --demo) DEMO=1; shift ;;
        --panel) [[ ${2:-} =~ ^[0-9]+$ ]] || usage; PANEL=$2; shift 2 ;;
        --breakdown) BREAKDOWN=1; shift ;;
        *) usage ;;
    esac
done
if [ -n "${PYTHON:-}" ]; then PY=$PYTHON; elif [ -x .venv/bin/python ]; then PY=.venv/bin/python; else PY=python3; fi
mkdir -p "$OUT"
SUMMARY=$OUT/summary.txt
FAILED=0

# step NAME COMMAND...: run it with its output in OUTDIR/NAME.txt (stderr in NAME.log); one summary line
step() {
    local name=$1; shift
    local start=$SECONDS
    "$@" >"$OUT/$name.txt" 2>"$OUT/$name.log"
    local rc=$?
    [ $rc = 0 ] || FAILED=$((FAILED + 1))
    printf '%-28s exit %d  %4d s  %s\n' "$name" "$rc" $((SECONDS - start)) "$*" | tee -a "$SUMMARY"
    return $rc
}

{ echo "device report, $(date -u '+%Y-%m-%d %H:%M UTC'), commit $(git rev-parse --short HEAD 2>/dev/null)"
  echo "options: device=${DEVICE:-auto} size=$SIZE bands=$BANDS repeat=$REPEAT ranks=$RANKS backends=$BACKENDS" \
       "tests=$TESTS demo=$DEMO panel=$PANEL breakdown=$BREAKDOWN"
  echo "machine: $(uname -srm), $(nproc) cores"; } >"$SUMMARY"
if [ $INSTALL = 1 ]; then
    step install env VKFFT_BACKEND=opencl "$PY" -m pip install -e '.[vkfft]'
fi
eval "$("$PY" -m clsdcam.backends.cl_icd "$OUT/vendors")"
step devices "$PY" -m clsdcam devices
# the chosen device as PYOPENCL_CTX's "platform index:device index", so that every step below runs on it
CTX=$("$PY" - "$DEVICE" <<'EOF'
import sys

import pyopencl as cl

from clsdcam.backends.cl_devices import choose_device

chosen = choose_device(sys.argv[1] or None)
platform = [p.int_ptr for p in cl.get_platforms()].index(chosen.platform.int_ptr)
print(f"{platform}:{[d.int_ptr for d in chosen.platform.get_devices()].index(chosen.int_ptr)}")
EOF
) || { echo "no device matches '${DEVICE}': see $OUT/devices.txt" | tee -a "$SUMMARY"; exit 1; }
export PYOPENCL_CTX=$CTX
{ echo "PYOPENCL_CTX=$CTX"; command -v nvidia-smi >/dev/null && nvidia-smi --query-gpu=name,driver_version,memory.total --format=csv; } \
    >>"$SUMMARY"
"$PY" -m pip freeze 2>/dev/null | grep -iE '^(numpy|scipy|pyopencl|reikna|pyvkfft|pocl|intel-opencl)' >"$OUT/packages.txt"

step check "$PY" -m clsdcam check --json "$OUT/check.json"
for engine in $("$PY" -c "from clsdcam.backends.fft import available_engines; print(*available_engines('device'))"); do
    step "kernels-device-$engine" "$PY" tools/bench_kernels.py --path device --engine "$engine" --size "$SIZE" \
        --bands "$BANDS" --repeat "$REPEAT" --json "$OUT/kernels-device-$engine.json"
done
step iteration "$PY" tools/bench_iteration.py --size "$SIZE" --bands "$BANDS" --ranks "$RANKS" --repeat "$REPEAT" \
    --backends "$BACKENDS" --no-authors --json "$OUT/iteration.json"
SCRATCH=$(mktemp -d)
trap 'rm -rf "$SCRATCH"' EXIT
if [ $TESTS = 1 ]; then
    step tests "$PY" -m pytest -q -p no:cacheprovider -rs tests/test_parity.py tests/test_devcheck.py
fi
if [ $DEMO = 1 ]; then
    step demo-today "$PY" -m clsdcam demo "$SCRATCH/demo-today" --size "$SIZE" --bands "$BANDS" --iters 300 \
        --algorithm fista --backend opencl
    step demo "$PY" -m clsdcam demo "$SCRATCH/demo" --size "$SIZE" --bands "$BANDS" --backend opencl
fi
if [ $BREAKDOWN = 1 ]; then
    step breakdown "$PY" tools/bench_breakdown.py --backend opencl --size "$SIZE" --bands "$BANDS" --iters 300 \
        --ranks '' --json "$OUT/breakdown.json"
fi
if [ "$PANEL" -gt 0 ]; then
    step panel "$PY" tools/bench_converged.py --backend opencl --size "$SIZE" --bands "$BANDS" --scenes "$PANEL" \
        --out "$OUT/panel" --cache "$SCRATCH/cache"
fi
echo "$FAILED step(s) failed; everything is in $OUT" | tee -a "$SUMMARY"
exit "$FAILED"
