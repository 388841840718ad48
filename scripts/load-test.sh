#!/usr/bin/env bash
# The tests timed against the host clock, on a busy machine: runs the tests that docs/testing.md
# lists under "Tests timed against the host clock" N times, each run beside four busy loops (the
# load the project's tests must stand: two cores, four loops), and writes `test,runs,failures`
# to CSV (default out/load_test.csv). Each run's output is kept in out/load_test_logs/.
#
#   scripts/load-test.sh N [CSV]
#
# The listed tests run together in one process with libtest's default threads, as the test
# command runs them, so a QEMU firmware shares the cores with other captures as well as the
# loops. Exits non-zero when any run of any test failed.
set -euo pipefail
cd "$(dirname "$0")/.."
usage="usage: scripts/load-test.sh N [CSV]"
N=${1:?$usage}
[[ "$N" =~ ^[1-9][0-9]*$ ]] || { echo "$usage (N a positive count of runs, not '$N')" >&2; exit 2; }
CSV=${2:-out/load_test.csv}
LOGS=out/load_test_logs

# The table's first column names each test as `module::function` of the integration tests.
mapfile -t tests < <(awk '/<!-- timed-tests -->/ {p = 1; next} /<!-- \/timed-tests -->/ {p = 0} p' docs/testing.md \
  | sed -n 's/^| `\([a-z0-9_]*::[a-z0-9_]*\)`.*/\1/p')
[ ${#tests[@]} -gt 0 ] || { echo "docs/testing.md lists no timed tests between its timed-tests markers" >&2; exit 1; }

bin=$(cargo test --release --all-features --test it --no-run 2>&1 \
  | sed -n 's/.*Executable tests\/it\/main.rs (\(.*\))/\1/p' | tail -n 1)
[ -x "$bin" ] || { echo "could not build the integration tests (cargo test --release --all-features --test it --no-run)" >&2; exit 1; }
listed=$("$bin" --list 2>/dev/null | sed -n 's/: test$//p')
for t in "${tests[@]}"; do
  grep -qxF "$t" <<<"$listed" || { echo "docs/testing.md lists $t, which is not a test of tests/it" >&2; exit 1; }
done

loops=()
stop_loops() { [ ${#loops[@]} -eq 0 ] || kill "${loops[@]}" 2>/dev/null || true; }
trap stop_loops EXIT
for _ in 1 2 3 4; do
  sh -c 'while :; do :; done' &
  loops+=($!)
done

mkdir -p "$LOGS"
declare -A failures
for t in "${tests[@]}"; do failures[$t]=0; done
for run in $(seq 1 "$N"); do
  log="$LOGS/run-$run.log"
  start=$(date +%s)
  "$bin" --exact "${tests[@]}" >"$log" 2>&1 || true
  failed=0
  for t in "${tests[@]}"; do
    if ! grep -qxF "test $t ... ok" "$log"; then
      failures[$t]=$((failures[$t] + 1))
      failed=$((failed + 1))
    fi
  done
  echo "run $run of $N: ${#tests[@]} tests, $failed failed, $(($(date +%s) - start)) s (output in $log)" >&2
done

mkdir -p "$(dirname "$CSV")"
{
  echo "test,runs,failures"
  for t in "${tests[@]}"; do echo "$t,$N,${failures[$t]}"; done
} >"$CSV"
total=0
for t in "${tests[@]}"; do total=$((total + failures[$t])); done
echo "wrote $CSV: $total failures in $N runs of ${#tests[@]} tests, under four busy loops" >&2
[ "$total" -eq 0 ]
