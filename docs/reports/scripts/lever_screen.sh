# Shared by the lever screens (lever_*.sh), which source it. `screen OUT NAME LABEL` runs the
# print-base recipe (photos and their turns, three white boxes) into OUT/base, unless it is there
# or BASE names a run of it to link, and the config OUT/configs/NAME.toml into OUT/NAME, each a
# 3-fold crossval at seed 0 scored by the main and the wide detector sets; then table1 of the
# two, the variant labelled LABEL.
pav=${PAV:-target/release/pav}
base=configs/studies/print-base.toml

# `variant OUT NAME < BODY`: the config OUT/configs/NAME.toml, the base recipe extended by BODY.
variant() {
  mkdir -p "$1/configs"
  { echo "extends = \"$(realpath $base)\""; cat; } > "$1/configs/$2.toml"
}

screen() {
  local out=$1 name=$2 label=$3
  local common=(--folds 3 --random-seeds 1 --reference data:rauca-e2e/RAUCA_E2E.png -d configs/detectors -d configs/detectors-wide)
  if [ -n "${BASE:-}" ] && [ ! -e "$out/base" ]; then ln -s "$(realpath "$BASE")" "$out/base"; fi
  [ -f "$out/base/crossval.csv" ] || "$pav" crossval --config $base "${common[@]}" -o "$out/base"
  [ -f "$out/$name/crossval.csv" ] || "$pav" crossval --config "$out/configs/$name.toml" "${common[@]}" -o "$out/$name"
  "$pav" table1 "$out/base" "$out/$name" --label base --label "$label" --against base -o "$out/table1"
}
