#!/usr/bin/env bash
# Replay the golden corpus (tests/fixtures/golden/*.mcap, recorded on x86-64) on an emulated
# arm64 Debian userland, with the JIT and with NUMBA_DISABLE_JIT=1.  `make test-arm64` runs it.
#
# What it does, each phase skipped when its stamp file shows it already done:
#   1. host packages: qemu-user-static, binfmt-support, debootstrap (apt-get; needs root);
#   2. the arm64 userland: debootstrap --foreign bookworm into $ROOT, then its second stage
#      under qemu (about 25 min on a loaded 2-core machine);
#   3. a venv in the userland with the project's dependencies from PyPI (aarch64 wheels), pinned
#      to the versions of the host's .venv when there is one, so both sides run the same numba;
#   4. the project as committed (git archive HEAD, a clean checkout) copied into the userland,
#      and `isaac replay` of every golden log, with the JIT and without.
# Exit status: 0 when every log replays identical both ways, 1 otherwise, 2 on a setup failure.
#
# Environment: ARM64_ROOT (default /var/tmp/isaac-arm64), DEBIAN_MIRROR (default: the host's
# apt source).  The userland is kept for the next run; delete $ARM64_ROOT to start afresh.
set -euo pipefail

REPO=$(cd "$(dirname "$0")/.." && pwd)
ROOT=${ARM64_ROOT:-/var/tmp/isaac-arm64}
SUITE=bookworm

log() { printf '[arm64 %s] %s\n' "$(date -u +%H:%M:%S)" "$*"; }
die() { printf 'arm64_replay: %s\n' "$*" >&2; exit 2; }

[ "$(id -u)" = 0 ] || die "needs root (debootstrap, chroot, mounts)"
[ "$(uname -m)" = x86_64 ] || log "host is $(uname -m), not x86_64: the comparison still runs"

mirror() {
    if [ -n "${DEBIAN_MIRROR:-}" ]; then echo "$DEBIAN_MIRROR"; return; fi
    local uri
    uri=$(grep -h -m1 -E '^URIs: .*/debian/?$' /etc/apt/sources.list.d/*.sources 2>/dev/null \
        | awk '{print $2}' || true)
    [ -z "$uri" ] && uri=$(grep -h -m1 -E '^deb .*/debian ' /etc/apt/sources.list 2>/dev/null \
        | awk '{print $2}' || true)
    echo "${uri:-http://deb.debian.org/debian}"
}

# 1. host packages
if ! command -v qemu-aarch64-static >/dev/null || ! command -v debootstrap >/dev/null \
    || ! command -v update-binfmts >/dev/null; then
    log "installing qemu-user-static binfmt-support debootstrap"
    apt-get update -qq
    DEBIAN_FRONTEND=noninteractive apt-get install -y -qq qemu-user-static binfmt-support \
        debootstrap >/dev/null
fi
if [ ! -e /proc/sys/fs/binfmt_misc/register ]; then
    mount -t binfmt_misc binfmt_misc /proc/sys/fs/binfmt_misc
fi
if [ ! -e /proc/sys/fs/binfmt_misc/qemu-aarch64 ]; then
    update-binfmts --enable qemu-aarch64 || die "cannot register qemu-aarch64 with binfmt_misc"
fi

# 2. the userland
mkdir -p "$ROOT"
if [ ! -e "$ROOT/.stage1" ]; then
    log "debootstrap stage 1 from $(mirror)"
    debootstrap --arch=arm64 --foreign --variant=minbase \
        --include=python3,python3-venv,python3-pip,ca-certificates "$SUITE" "$ROOT" "$(mirror)"
    touch "$ROOT/.stage1"
fi
cp /usr/bin/qemu-aarch64-static "$ROOT/usr/bin/"
if [ ! -e "$ROOT/.stage2" ]; then
    log "debootstrap stage 2 under qemu (slow: about 25 min)"
    chroot "$ROOT" /debootstrap/debootstrap --second-stage
    touch "$ROOT/.stage2"
fi

mounted=()
cleanup() {
    local i
    for ((i = ${#mounted[@]} - 1; i >= 0; i--)); do umount -l "${mounted[$i]}" || true; done
}
trap cleanup EXIT
for m in proc sys dev dev/pts; do
    if ! mountpoint -q "$ROOT/$m"; then
        case $m in
            proc) mount -t proc proc "$ROOT/proc" ;;
            sys) mount -t sysfs sys "$ROOT/sys" ;;
            *) mount --bind "/$m" "$ROOT/$m" ;;
        esac
        mounted+=("$ROOT/$m")
    fi
done
# pip's HTTPS needs the host's CA bundle (the userland's may lack a proxy's certificate)
cp /etc/ssl/certs/ca-certificates.crt "$ROOT/etc/ssl/certs/ca-certificates.crt"
in_root() { chroot "$ROOT" env -i HOME=/root PATH=/opt/venv/bin:/usr/bin:/bin LANG=C.UTF-8 "$@"; }

# 3. the dependencies, from PyPI
pins=$(cd "$REPO" && python3 - <<'EOF'
import re, subprocess, sys, tomllib
deps = tomllib.load(open("pyproject.toml", "rb"))["project"]["dependencies"]
names = [re.split(r"[<>=!~ \[]", d, maxsplit=1)[0] for d in deps]
try:
    out = subprocess.run([".venv/bin/python", "-m", "pip", "freeze"], capture_output=True,
                         text=True, check=True).stdout
    have = {l.split("==")[0].lower(): l for l in out.splitlines() if "==" in l}
except (OSError, subprocess.CalledProcessError):
    have = {}
# numba's llvmlite is pinned too: the compiler decides the instructions
pinned = [have.get(n.lower(), d) for n, d in zip(names, deps)]
pinned += [have[n] for n in ("llvmlite",) if n in have]
print(" ".join(pinned))
EOF
)
if [ ! -e "$ROOT/.deps" ] || [ "$(cat "$ROOT/.deps")" != "$pins" ]; then
    log "installing into the userland's venv: $pins"
    in_root python3 -m venv /opt/venv
    # shellcheck disable=SC2086
    in_root env PIP_CERT=/etc/ssl/certs/ca-certificates.crt PIP_DISABLE_PIP_VERSION_CHECK=1 \
        PIP_DEFAULT_TIMEOUT=180 python -m pip install --quiet --only-binary=:all: $pins
    echo "$pins" >"$ROOT/.deps"
fi

# 4. the project as committed, and the replays
rm -rf "$ROOT/opt/isaac"
mkdir -p "$ROOT/opt/isaac"
git -C "$REPO" archive HEAD | tar -x -C "$ROOT/opt/isaac"
logs=$(cd "$ROOT/opt/isaac" && ls tests/fixtures/golden/*.mcap 2>/dev/null || true)
[ -n "$logs" ] || die "no tests/fixtures/golden/*.mcap in HEAD"
in_root python -c 'import platform, numpy, numba, sys
print("userland:", platform.machine(), "Python", sys.version.split()[0], "numpy", numpy.__version__,
      "numba", numba.__version__, "glibc", platform.libc_ver()[1])'

status=0
for mode in jit nojit; do
    for f in $logs; do
        start=$(date +%s)
        if [ $mode = nojit ]; then extra="NUMBA_DISABLE_JIT=1"; else extra="NUMBA_CACHE_DIR=/tmp/nb"; fi
        # shellcheck disable=SC2086
        if out=$(in_root env $extra PYTHONPATH=/opt/isaac sh -c \
            "cd /opt/isaac && python -m isaac replay $f" 2>&1); then rc=0; else rc=$?; fi
        verdict=$(printf '%s\n' "$out" | head -n 1)
        log "$mode $f: exit $rc, $(($(date +%s) - start)) s: $verdict"
        [ $rc = 0 ] || { status=1; printf '%s\n' "$out" | tail -n 20; }
    done
done
if [ $status = 0 ]; then log "every golden log replayed identical on arm64, JIT and no JIT"; fi
exit $status
