#!/usr/bin/env bash
# A benchmark video: SOURCE (default the CARLA fixture, 45 frames of 800×800) looped ROUNDS
# times, made once at PATH.
#   scripts/loop_video.sh PATH ROUNDS [SOURCE]
set -euo pipefail
if [ ! -f "$1" ]; then
  mkdir -p "$(dirname "$1")"
  ffmpeg -loglevel error -y -stream_loop $(($2 - 1)) -i "${3:-$(dirname "$0")/../fixtures/carla_orbit.mp4}" -c copy "$1"
fi
