#!/usr/bin/env bash
# Embedded measurements for BENCHMARKS.md: sizes, stack, instructions per evaluate.
# Usage: firmware-example/tools/measure.sh   (needs qemu-system-arm, binutils-arm-none-eabi, cc)
set -euo pipefail
cd "$(dirname "$0")/../.."
T=${CARGO_TARGET_DIR:-target}
cc -shared -fPIC -O2 -o "$T/libinsn_count.so" firmware-example/tools/insn_count.c
for variant in libm fast; do
  dir="$T/measure-$variant"
  feat=(); [ "$variant" = fast ] && feat=(--features fast-tanh)
  CARGO_TARGET_DIR="$dir" cargo build -q -p firmware-example --release --target thumbv7em-none-eabihf --bins "${feat[@]}"
  bin="$dir/thumbv7em-none-eabihf/release"
  echo "== $variant tanh"
  arm-none-eabi-size "$bin/firmware-example" "$bin/evaluate-bench"
  arm-none-eabi-nm -S "$bin/evaluate-bench" | grep -E " (ampc_evaluate|.*tanhf.*|.*expm1f.*)$" || true
  for n in 1 1001; do
    qemu-system-arm -cpu cortex-m4 -machine mps2-an386 -nographic \
      -semihosting-config enable=on,target=native,arg=evaluate-bench,arg=$n \
      -plugin "$T/libinsn_count.so" -d plugin -kernel "$bin/evaluate-bench" 2>&1 | tr '\n' ' '
    echo
  done
done
