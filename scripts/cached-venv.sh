# Sourced by scripts/esphome.sh and scripts/ros2-venv.sh: a tool that is not a
# project dependency, pinned, in a venv of its own under the cache (outside
# the clone, so a fresh clone, CI's, installs it once per machine).
#
#   cached_venv VENV LABEL SKIPS CHECK PACKAGE...
#
# Makes VENV with PACKAGE... unless it is complete, then runs the Python CHECK
# in it; status 0 when VENV is ready. Offline, or where pip or CHECK fails: the
# log's last lines and one line naming LABEL and what SKIPS, VENV removed,
# status 1. `.complete` is written last: a half-made venv is made again.
cached_venv() {
    local venv=$1 label=$2 skips=$3 check=$4 python log
    shift 4
    [ -f "$venv/.complete" ] && return 0
    echo "buddybot: installing $label in $venv (once)..." >&2
    rm -rf "$venv"
    mkdir -p "$(dirname "$venv")"
    python=$(command -v python3.11 || command -v python3)
    log="$venv.install.log"
    if ! { "$python" -m venv "$venv" &&
           "$venv/bin/pip" install -q --disable-pip-version-check "$@" &&
           "$venv/bin/python" -c "$check"; } >"$log" 2>&1; then
        tail -n 5 "$log" >&2
        rm -rf "$venv"
        echo "buddybot: $label could not be installed (offline?), see $log: $skips" >&2
        return 1
    fi
    touch "$venv/.complete"
}
