#!/usr/bin/env bash
# Embedded measurements for BENCHMARKS.md: sizes, stack, instructions per evaluate, on the
# Cortex-M4F (thumbv7em-none-eabihf, QEMU mps2-an386) and the Cortex-M0 (thumbv6m-none-eabi,
# soft-float, QEMU microbit), each with the default (accurate) and the fast tanh.
# Usage: firmware-example/tools/measure.sh [m4|m0 ...]   (default: both; needs
# qemu-system-arm, binutils-arm-none-eabi, cc, and both rustup targets)
#        firmware-example/tools/measure.sh safe [m4|m0 ...]: the safety-augmented step
# (`safe-bench`: the check alone and with the sequence network, quadrotor and pendulum),
# instructions per step = (count(1001) − count(1))/1000.
set -euo pipefail
cd "$(dirname "$0")/../.."
T=${CARGO_TARGET_DIR:-target}
mkdir -p "$T"
cc -shared -fPIC -O2 -o "$T/libinsn_count.so" firmware-example/tools/insn_count.c
count() { # qemu args... → the plugin's instruction count
  qemu-system-arm "$@" 2>&1 | tr '\n' ' ' | grep -oE 'insns: ?[0-9]+' | grep -oE '[0-9]+' | tail -1
}
if [ "${1:-}" = safe ]; then
  shift
  boards=("$@"); [ ${#boards[@]} -eq 0 ] && boards=(m4 m0)
  for board in "${boards[@]}"; do
    case $board in
      m4) target=thumbv7em-none-eabihf; qemu=(-cpu cortex-m4 -machine mps2-an386) ;;
      m0) target=thumbv6m-none-eabi; qemu=(-cpu cortex-m0 -machine microbit) ;;
      *) echo "unknown board $board (m4 or m0)" >&2; exit 2 ;;
    esac
    dir="$T/measure-accurate"
    CARGO_TARGET_DIR="$dir" cargo build -q -p firmware-example --release --target "$target" --bin safe-bench
    elf="$dir/$target/release/safe-bench"
    for mode in "" "net" "pendulum" "pendulum,arg=net"; do
      a=(); [ -n "$mode" ] && a=(",arg=$mode")
      c1=$(count "${qemu[@]}" -nographic -semihosting-config "enable=on,target=native,arg=safe-bench${a[*]:-},arg=1" \
        -plugin "$T/libinsn_count.so" -d plugin -kernel "$elf")
      c2=$(count "${qemu[@]}" -nographic -semihosting-config "enable=on,target=native,arg=safe-bench${a[*]:-},arg=1001" \
        -plugin "$T/libinsn_count.so" -d plugin -kernel "$elf")
      echo "$board safe-bench ${mode:-quadrotor check}: $(( (c2 - c1) / 1000 )) instructions per step (counts $c1, $c2)"
    done
  done
  exit 0
fi
boards=("$@"); [ ${#boards[@]} -eq 0 ] && boards=(m4 m0)
for board in "${boards[@]}"; do
  case $board in
    m4) target=thumbv7em-none-eabihf; qemu=(-cpu cortex-m4 -machine mps2-an386) ;;
    m0) target=thumbv6m-none-eabi; qemu=(-cpu cortex-m0 -machine microbit) ;;
    *) echo "unknown board $board (m4 or m0)" >&2; exit 2 ;;
  esac
  for variant in accurate fast; do
    dir="$T/measure-$variant"
    feat=(); [ "$variant" = fast ] && feat=(--features fast-tanh)
    CARGO_TARGET_DIR="$dir" cargo build -q -p firmware-example --release --target "$target" --bins "${feat[@]}"
    bin="$dir/$target/release"
    echo "== $board ($target), $variant tanh"
    arm-none-eabi-size "$bin/firmware-example" "$bin/evaluate-bench"
    arm-none-eabi-nm -S --size-sort "$bin/evaluate-bench" | grep -E " (ampc_evaluate|.*tanh.*|.*expm1f.*|__aeabi_f.*|__.*sf3.*)$" || true
    for n in 1 1001; do
      qemu-system-arm "${qemu[@]}" -nographic \
        -semihosting-config enable=on,target=native,arg=evaluate-bench,arg=$n \
        -plugin "$T/libinsn_count.so" -d plugin -kernel "$bin/evaluate-bench" 2>&1 | tr '\n' ' '
      echo
    done
  done
done
