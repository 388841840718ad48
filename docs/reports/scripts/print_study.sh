#!/usr/bin/env bash
# The print-channel study (docs/reports/print.md): for each seed, cross-validate (3 folds over
# FCA's 11 photos) the quick recipe on photos trained without the print channel, through it,
# and through it with the gamut term at three weights; every texture, RAUCA-E2E's and the random
# ones included, is scored as printed through Ghostscript's CMYK profile. The run without the
# channel is scored once more unprinted (its folds resume; only the scoring runs again).
# usage: docs/reports/scripts/print_study.sh OUT SEED... (run from the repository root)
set -euo pipefail
out=$1; shift
pav=${PAV:-target/release/pav}
mkdir -p "$out/configs"
cfgdir=$(cd "$out/configs" && pwd)
studies=$(cd configs/studies && pwd)
common=(--folds 3 --random-seeds 1 --reference data:rauca-e2e/RAUCA_E2E.png)
config() { # name base gamut_weight seed
  {
    echo "extends = \"$studies/$2.toml\""
    if [ "$3" != "-" ]; then printf '\n[print]\ngamut_weight = %s\n' "$3"; fi
    printf '\n[optimizer]\nseed = %s\n' "$4"
  } > "$cfgdir/$1.toml"
  echo "$cfgdir/$1.toml"
}
for s in "$@"; do
  c=$(config base-s$s print-base - $s)
  [ -f "$out/base-printed-s$s/crossval.csv" ] || "$pav" crossval --config "$c" "${common[@]}" --print -o "$out/base-printed-s$s"
  if [ ! -f "$out/base-s$s/crossval.csv" ]; then
    mkdir -p "$out/base-s$s" && cp -r "$out/base-printed-s$s"/fold* "$out/base-s$s/"
    "$pav" crossval --config "$c" "${common[@]}" -o "$out/base-s$s"
  fi
  for w in 0 0.03 0.1 0.3; do
    name=channel-g$w-s$s
    c=$(config $name print-channel $w $s)
    [ -f "$out/$name/crossval.csv" ] || "$pav" crossval --config "$c" "${common[@]}" -o "$out/$name"
  done
done
