#!/usr/bin/env bash
# The benchmarks' default video: the CARLA fixture (45 frames, 800×800) looped to ROUNDS·45
# frames, made once at PATH.
#   scripts/loop_video.sh PATH ROUNDS
set -euo pipefail
if [ ! -f "$1" ]; then
  mkdir -p "$(dirname "$1")"
  ffmpeg -loglevel error -y -stream_loop $(($2 - 1)) -i "$(dirname "$0")/../fixtures/carla_orbit.mp4" -c copy "$1"
fi
