# The defence study's three recipes as optimize configs, sourced by defence_study.sh and
# defence_turntable.sh: configs/studies/print-base.toml at a seed, trained without defences
# (plain), through median smoothing (median) and through feature norm clipping (clip).
# usage (after `source`): defence_configs OUT SEED  -> writes OUT/configs/{plain,median,clip}-sSEED.toml
defence_configs() {
  local out=$1 s=$2 repo cfgdir
  repo=$(pwd)
  mkdir -p "$out/configs"
  cfgdir=$(cd "$out/configs" && pwd)
  white_boxes() { # defence-toml-or-empty yolov3-config deimv2-config
    for d in "$2" "$repo/configs/detectors/yolov8n_int8.toml" "$3"; do
      printf '\n[[white_box]]\ndetector = "%s"\nweight = 1.0\n' "$d"
      case $d in *int8*) echo 'surrogate = true' ;; esac
      [ -n "$1" ] && echo "defence = [$1]"
    done
  }
  config() { # name white-box-lines
    { echo "extends = \"$repo/configs/studies/print-base.toml\""; printf '\n[optimizer]\nseed = %s\n' "$s"; echo "$2"; } \
      > "$cfgdir/$1-s$s.toml"
  }
  local d=$repo/configs/detectors c=$repo/configs/defences
  config plain "$(white_boxes "" "$d/yolov3-tiny.toml" "$d/deimv2_atto_int8.toml")"
  config median "$(white_boxes '{ kind = "median", k = 3 }' "$d/yolov3-tiny.toml" "$d/deimv2_atto_int8.toml")"
  config clip "$(white_boxes "" "$c/yolov3-tiny-clip.toml" "$c/deimv2_atto_int8-clip.toml")"
}
