#!/usr/bin/env bash
# The README's two Quick start commands on "another CPU", on this machine: each profile makes
# numpy, OpenBLAS and numba take another CPU's code paths, in a fresh clone with a fresh venv,
# then checks that `git status --short` prints nothing (issue 22: "on a machine of another CPU
# type the README's two commands are green and leave git status clean").
#
#   benchmarks/other_cpus.sh PROFILE [SOURCE]
#
# PROFILE, software dispatch (native speed; the suite runs whole, with -n 2):
#   avx512-intel  an Intel Xeon with AVX-512 (the issue's machine): OPENBLAS_CORETYPE=SkylakeX,
#                 NUMBA_CPU_NAME=skylake-avx512; numpy keeps its AVX-512 paths
#   haswell       an AVX2 Intel Haswell: numpy without its X86_V4/AVX512_* paths
#                 (NPY_DISABLE_CPU_FEATURES), OPENBLAS_CORETYPE=Haswell, NUMBA_CPU_NAME=haswell
#   baseline      an x86-64-v2 machine (Nehalem-like): numpy on its SSE4.2 baseline (every
#                 dispatched group above it disabled), OPENBLAS_CORETYPE=Prescott (the oldest
#                 SSE3 kernel), NUMBA_CPU_NAME=nehalem
#   nehalem       baseline, and glibc's libm on the code paths of a CPU without AVX2 and FMA
#                 (GLIBC_TUNABLES=glibc.cpu.hwcaps=-AVX2,-FMA: its sin, cos, exp and log
#                 choose their SSE2 variants, whose last bits differ from the FMA ones): what
#                 qemu-nehalem showed, at native speed
# PROFILE, emulation (qemu-user's TCG: cpuid reports that CPU, so numpy, OpenBLAS and numba
# all choose their paths as on it; slow, so the suite runs only the reproduction and
# extraction tests):
#   qemu-nehalem  qemu-x86_64 -cpu Nehalem (SSE4.2, no AVX)
#   qemu-haswell  qemu-x86_64 -cpu Haswell-noTSX (AVX2, FMA), less the features TCG lacks
#
# SOURCE is the repository to clone (default: the one this script is in; its HEAD is what
# runs). The clone is /tmp/other-cpus/PROFILE, its venv /tmp/other-cpus/PROFILE.venv; the log
# of each step goes to /tmp/other-cpus/PROFILE.log. Exit status 0 only when both commands
# passed and git status is clean. These variables are set for this script's commands only:
# never in the tests or in CI. pip installs natively (its speed is not what is tested); under
# qemu every Python process, the workers and the test runner's subprocesses included, runs
# emulated (a wrapper named as sys.executable; see below).
set -euo pipefail

profile="${1:?usage: benchmarks/other_cpus.sh PROFILE [SOURCE]}"
source_repo="${2:-$(git -C "$(dirname "$0")" rev-parse --show-toplevel)}"
work=/tmp/other-cpus
clone="$work/$profile"
venv="$clone.venv"
log="$work/$profile.log"

# numpy 2.x dispatches by groups (show_runtime's simd_extensions): X86_V2 is its baseline
avx512_groups="X86_V4 AVX512_ICL AVX512_SPR"
qemu_model=""
case "$profile" in
    avx512-intel)
        profile_env=(OPENBLAS_CORETYPE=SkylakeX NUMBA_CPU_NAME=skylake-avx512) ;;
    haswell)
        profile_env=("NPY_DISABLE_CPU_FEATURES=$avx512_groups" OPENBLAS_CORETYPE=Haswell
                     NUMBA_CPU_NAME=haswell) ;;
    baseline)
        profile_env=("NPY_DISABLE_CPU_FEATURES=X86_V3 $avx512_groups" OPENBLAS_CORETYPE=Prescott
                     NUMBA_CPU_NAME=nehalem) ;;
    nehalem)
        profile_env=("NPY_DISABLE_CPU_FEATURES=X86_V3 $avx512_groups" OPENBLAS_CORETYPE=Prescott
                     NUMBA_CPU_NAME=nehalem GLIBC_TUNABLES=glibc.cpu.hwcaps=-AVX2,-FMA) ;;
    qemu-nehalem)
        qemu_model=Nehalem; profile_env=() ;;
    qemu-haswell)
        # the features of the model that TCG cannot emulate (it warns on stderr otherwise,
        # which the CLI tests' one-line-error checks would read)
        qemu_model=Haswell-noTSX,-invpcid,-pcid,-x2apic,-tsc-deadline; profile_env=() ;;
    *)
        echo "unknown profile $profile (avx512-intel, haswell, baseline, nehalem, qemu-nehalem," \
             "qemu-haswell)" >&2
        exit 2 ;;
esac

mkdir -p "$work"
rm -rf "$clone" "$venv"
exec > >(tee "$log") 2>&1
echo "== $profile: $(date -u +%FT%TZ), clone of $source_repo"
git clone --quiet "$source_repo" "$clone"
git -C "$clone" log --oneline -1
python3 -m venv "$venv"
cd "$clone"
"$venv/bin/python" -m pip install --quiet '.[fast]'
"$venv/bin/python" -m pip install --quiet threadpoolctl  # only to report the BLAS kernel

python_cmd=("$venv/bin/python")
if [ -n "$qemu_model" ]; then
    command -v qemu-x86_64 >/dev/null || { echo "needs qemu-user (apt-get install qemu-user)"; exit 2; }
    # Python takes sys.executable from argv[0] (qemu's -0), and finds the venv from its
    # directory: every subprocess started with sys.executable (the worker pool, xdist, the
    # CLI tests) goes through qemu too
    python_version="$("$venv/bin/python" -c 'import sys; print("%d.%d" % sys.version_info[:2])')"
    cat > "$venv/bin/python-qemu" <<EOF
#!/bin/sh
exec qemu-x86_64 -cpu '$qemu_model' -0 "\$0" "\$(dirname "\$0")/python$python_version" "\$@"
EOF
    chmod +x "$venv/bin/python-qemu"
    python_cmd=("$venv/bin/python-qemu")
fi
run() { env "${profile_env[@]}" "$@"; }

echo "== the code paths taken"
run "${python_cmd[@]}" - <<'EOF'
import os

import llvmlite.binding as llvm
import numba
import numpy as np
import scipy.linalg  # noqa: F401  (loads scipy's own OpenBLAS)
import threadpoolctl

from numpy._core._multiarray_umath import __cpu_baseline__, __cpu_dispatch__, __cpu_features__

# __cpu_features__ is what the CPU has; NPY_DISABLE_CPU_FEATURES removes groups from dispatch
disabled = set(os.environ.get("NPY_DISABLE_CPU_FEATURES", "").split())
print("numpy", np.__version__, "baseline", __cpu_baseline__, "dispatch used",
      [g for g in __cpu_dispatch__ if __cpu_features__.get(g) and g not in disabled])
for blas in threadpoolctl.threadpool_info():
    if blas["internal_api"] == "openblas":
        print("openblas", blas["version"], blas["architecture"], os.path.basename(blas["filepath"]))
# glibc picks its sin/cos by the CPU's features (ifunc): a digest of math.sin over fixed
# arguments tells the FMA paths from the SSE2 ones (the same on two runs of one machine)
import hashlib, math, struct
digest = hashlib.sha256(struct.pack("4096d", *(math.sin(0.37 * k + 0.1) for k in range(4096))))
print("libm sin digest", digest.hexdigest()[:12], "GLIBC_TUNABLES",
      os.environ.get("GLIBC_TUNABLES", "(unset)"))
print("numba", numba.__version__, "host cpu", llvm.get_host_cpu_name(),
      "NUMBA_CPU_NAME", numba.config.CPU_NAME)
EOF

status=0
echo "== quick start 1: bounce reproduce"
start=$SECONDS
if [ -n "$qemu_model" ]; then
    run "${python_cmd[@]}" -m bounce_cli reproduce || status=1
else
    run "$venv/bin/bounce" reproduce || status=1
fi
echo "   $((SECONDS - start)) s wall"

"$venv/bin/python" -m pip install --quiet '.[test]'
start=$SECONDS
if [ -n "$qemu_model" ]; then
    echo "== quick start 2, the emulation subset: the reproduction and extraction tests"
    run "${python_cmd[@]}" -m pytest -n 2 -q \
        tests/test_reproduction.py tests/experiments/test_extract.py || status=1
else
    echo "== quick start 2: python -m pytest -n 2"
    run "${python_cmd[@]}" -m pytest -n 2 -q || status=1
fi
echo "   $((SECONDS - start)) s wall"

echo "== git status --short (must print nothing)"
dirty="$(git status --short)"
if [ -n "$dirty" ]; then
    echo "$dirty"
    status=1
fi
echo "== $profile: $([ $status = 0 ] && echo green and clean || echo FAILED) $(date -u +%FT%TZ)"
exit $status
