# Shared by .ci/run, .ci/smoke and .ci/lower-bounds (sourced, not run).
#
# step NAME CMD...   runs CMD (a command or a shell function) in a subshell with `set -e`, so
#                    that any failing command inside it fails the step; prints its wall time and
#                    appends "NAME<TAB>seconds" to $CI_TIMES when that is set (.ci/run prints
#                    them all at the end). Returns CMD's exit code. A step sets no variable for
#                    the next one (it runs in a subshell): steps hand on files.
# run_pytest ARGS... python -m pytest ARGS; exit code 5 (no test collected) is said, and fails.

_now() { date +%s.%N; }
_since() { awk -v a="$1" -v b="$(_now)" 'BEGIN { printf "%.1f", b - a }'; }

step() {
    local name=$1 t0 dt rc errexit=0
    shift
    [[ $- == *e* ]] && errexit=1
    echo "== ${name}"
    t0=$(_now)
    set +e
    (set -e; "$@")  # not inside `||` or `if`: there bash would ignore set -e in the function
    rc=$?
    ((errexit)) && set -e
    dt=$(_since "$t0")
    if [ -n "${CI_TIMES:-}" ]; then printf '%s\t%s\n' "$name" "$dt" >>"$CI_TIMES"; fi
    if [ "$rc" -ne 0 ]; then
        echo "== ${name}: FAILED (exit ${rc}) after ${dt} s" >&2
        return "$rc"
    fi
    echo "== ${name}: ${dt} s"
}

run_pytest() {
    local rc=0
    python -m pytest "$@" || rc=$?
    if [ "$rc" -eq 5 ]; then
        echo "pytest collected no test (exit 5) with: $*; that is a failure here" >&2
    fi
    return "$rc"
}
