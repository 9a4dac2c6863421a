#!/bin/bash
# run.sh DIR SECONDS RUNS - run both firmware fuzz targets at once, one per core.
#   DIR      where fuzz-frame, fuzz-seq and their .dict files are (logs go there too)
#   SECONDS  wall-time limit per target
#   RUNS     executions per fuzzer process (0: no limit); the first limit reached ends it
# The frame target is about four times faster per execution; when it is done
# before SECONDS, a second sequencer process takes its core for the time left,
# sharing the sequencer's corpus (libFuzzer reloads it), and the sequencer's
# figures are the sum of both processes.
# Seeds come from fuzz/corpus-<target>/, new inputs go to fuzz/work-<target>/.
# Prints one summary line per target; exits 1 if any process found a crash, a
# leak or a timeout (the input is saved as DIR/<target>-crash-*, -leak-*, -timeout-*).
set -u
if [ $# -ne 3 ]; then
    echo "usage: $0 DIR SECONDS RUNS" >&2
    exit 2
fi
dir=$(cd "$1" && pwd)
secs=$2
runs=$3
here=$(cd "$(dirname "$0")" && pwd)
# longest input per target: a few Modbus frames / a few dozen operations
declare -A max_len=([frame]=300 [seq]=512)
t_start=$SECONDS

bytes() { find "$1" -type f -printf '%s\n' | awk '{n += $1} END {print n + 0}'; }

# fuzz NAME LOG SECONDS: one libFuzzer process; its exit status
fuzz() {
    local name=$1 log=$2 limit=$3
    mkdir -p "$here/work-$name"
    local args=(-max_total_time="$limit" -max_len="${max_len[$name]}" -timeout=10
                -dict="$dir/$name.dict" -print_final_stats=1 -artifact_prefix="$dir/$name-")
    [ "$runs" -gt 0 ] && args+=(-runs="$runs")
    nice -n "${FUZZ_NICE:-5}" "$dir/fuzz-$name" "${args[@]}" "$here/work-$name" "$here/corpus-$name" \
        > "$log" 2>&1
}

# summary NAME RC T0 LOG...: one line per target, the figures summed over its processes
summary() {
    local name=$1 rc=$2 t0=$3
    shift 3
    local execs=0 done_line="" log n
    for log in "$@"; do
        n=$(sed -n 's/^stat::number_of_executed_units: *//p' "$log")
        execs=$((execs + ${n:-0}))
        done_line=$(grep -E '^#[0-9]+[[:space:]]+DONE' "$log" | tail -1)
    done
    local wall=$((SECONDS - t0))
    local work=$here/work-$name seeds=$here/corpus-$name
    echo "fuzz-$name: $([ "$rc" -eq 0 ] && echo clean || echo FAILED) in $wall s ($# process(es)):" \
         "$execs executions, $((execs / (wall > 0 ? wall : 1))) exec/s;" \
         "$(echo "$done_line" | grep -oE 'cov: [0-9]+ ft: [0-9]+ corp: [^ ]+');" \
         "corpus $(ls "$work" | wc -l) new + $(ls "$seeds" | wc -l) seed inputs" \
         "($(bytes "$work") + $(bytes "$seeds") bytes)"
    if [ "$rc" -ne 0 ]; then
        for log in "$@"; do
            grep -E 'ERROR|SUMMARY|invariant|assertion|Test unit written' "$log" | head -8
        done
        echo "logs: $*"
    fi
}

fuzz frame "$dir/fuzz-frame.log" "$secs" &
frame_pid=$!
fuzz seq "$dir/fuzz-seq.log" "$secs" &
seq_pid=$!
wait $frame_pid
frame_rc=$?
summary frame $frame_rc $t_start "$dir/fuzz-frame.log"
seq_logs=("$dir/fuzz-seq.log")
left=$((secs - (SECONDS - t_start)))
seq2_rc=0
if [ $left -ge 30 ] && kill -0 $seq_pid 2>/dev/null; then
    seq_logs+=("$dir/fuzz-seq-2.log")
    fuzz seq "$dir/fuzz-seq-2.log" "$left"
    seq2_rc=$?
fi
wait $seq_pid
seq_rc=$?
[ $seq2_rc -ne 0 ] && seq_rc=$seq2_rc
summary seq $seq_rc $t_start "${seq_logs[@]}"
[ $frame_rc -eq 0 ] && [ $seq_rc -eq 0 ]
