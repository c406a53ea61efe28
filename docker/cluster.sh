#!/usr/bin/env bash
# The set-up of docker/docker-compose.yml without Docker: a Ray head, K Ray workers and an MLflow
# tracking server (artifacts served by the server) as local processes of this machine. Used by
# docker/README.md and by tests/cluster/.
#
#   docker/cluster.sh start            head + $WORKERS workers + mlflow server; prints the env
#   docker/cluster.sh env              prints it again (KEY=VALUE lines)
#   docker/cluster.sh stop             stops everything this script started, nothing else
#   docker/cluster.sh stop NAME        stops one part: head, worker-1..K or mlflow
#   docker/cluster.sh start mlflow     (re)starts the mlflow server on the same port, store and artifacts
#   docker/cluster.sh kill NAME        SIGKILLs one node and its processes at once (a machine lost)
#
# Settings (environment, read by `start`; later commands read $LAC_CLUSTER_DIR/cluster.env):
#   LAC_CLUSTER_DIR   state, logs, Ray temp dirs, Tune storage, MLflow store, created 0700 and
#                     refused if another user owns it ($XDG_RUNTIME_DIR or /tmp, /lac-cluster-UID)
#   WORKERS           Ray worker nodes (1)          CPUS_PER_NODE  CPUs each node offers (1)
#   RAY_PORT          GCS port of the head (6379)   MLFLOW_PORT    tracking server port (5000)
#   OBJECT_STORE_MB   object store per node (1024)
#   DASHBOARD_PORT    Ray dashboard + job API port; empty = no dashboard (needs ray[default])
#   MLFLOW_BACKEND_URI  backend store (sqlite:///$LAC_CLUSTER_DIR/mlflow/mlflow.db; a postgresql://
#                     URI needs psycopg2 next to mlflow)
#   STOP_GRACE        seconds between SIGTERM and SIGKILL on stop (5)
#   RAY_AUTH_MODE     token (Ray's default): nodes, drivers and `ray job` calls share one token,
#                     RAY_AUTH_TOKEN if set, else ~/.ray/auth_token (created 0600 if missing).
#                     `disabled` turns it off.
#
# MLflow (and the optional dashboard) listen on 127.0.0.1 only. Ray's GCS and raylets listen on
# every interface and advertise the machine's IP (Ray replaces 127.0.0.1 by it), hence the token.
#
# Each part runs in its own process group (setsid), recorded in $LAC_CLUSTER_DIR/pids/NAME;
# `stop` signals those groups and the processes they spawned (Ray workers get groups of their
# own), so other Ray sessions on the machine are left alone. Never `ray stop`: it stops them all.
set -euo pipefail

REPO=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
if [ -x "$REPO/.venv/bin/ray" ]; then export PATH="$REPO/.venv/bin:$PATH"; fi
DIR=${LAC_CLUSTER_DIR:-${XDG_RUNTIME_DIR:-/tmp}/lac-cluster-$(id -u)}
HOST=127.0.0.1
umask 077  # state, logs, stores and the token are this user's only

die() { echo "cluster.sh: $*" >&2; exit 1; }

private_dir() {  # the state directory: created 0700; refused if another user owns it (a planted cluster.env)
    if [ ! -e "$DIR" ]; then mkdir -p -m 700 "$DIR"; fi
    [ -d "$DIR" ] && [ ! -L "$DIR" ] || die "$DIR is not a directory"
    [ "$(stat -c %u "$DIR")" = "$(id -u)" ] || die "$DIR belongs to another user (uid $(stat -c %u "$DIR")); refusing to use it"
    chmod 700 "$DIR"
}
free_port() { python -c 'import socket; s = socket.socket(); s.bind(("127.0.0.1", 0)); print(s.getsockname()[1])'; }
alive() { ps -o stat= -p "$1" 2>/dev/null | grep -v Z >/dev/null; }  # zombies count as gone

SETTINGS="WORKERS CPUS_PER_NODE OBJECT_STORE_MB RAY_PORT MLFLOW_PORT DASHBOARD_PORT MLFLOW_BACKEND_URI RAY_AUTH_MODE"

read_env() {  # cluster.env as data: only the known settings, KEY=VALUE, never executed (no `source`)
    local key value
    while IFS='=' read -r key value; do
        case " $SETTINGS " in *" $key "*) printf -v "$key" '%s' "$value"; export "${key?}" ;; esac
    done <"$DIR/cluster.env"
}

load_settings() {  # the settings of the running set-up (except for a full start), else the environment's
    private_dir
    if [ -f "$DIR/cluster.env" ] && [ "${1:-}" != fresh ]; then read_env; fi
    WORKERS=${WORKERS:-1} CPUS_PER_NODE=${CPUS_PER_NODE:-1} OBJECT_STORE_MB=${OBJECT_STORE_MB:-1024}
    RAY_PORT=${RAY_PORT:-6379} MLFLOW_PORT=${MLFLOW_PORT:-5000} DASHBOARD_PORT=${DASHBOARD_PORT:-}
    MLFLOW_BACKEND_URI=${MLFLOW_BACKEND_URI:-sqlite:///$DIR/mlflow/mlflow.db}
    export RAY_AUTH_MODE=${RAY_AUTH_MODE:-token}
}

ensure_token() {  # token mode without a token given: Ray's own file, generated once, this user's only
    if [ "$RAY_AUTH_MODE" = token ] && [ -z "${RAY_AUTH_TOKEN:-}${RAY_AUTH_TOKEN_PATH:-}" ]; then
        ray get-auth-token --generate >/dev/null
        chmod 600 "$HOME/.ray/auth_token"
    fi
}

launch() {  # NAME CMD...: run CMD in a new session (its pid is its process group id), log to logs/NAME.log
    local name=$1; shift
    if [ -f "$DIR/pids/$name" ] && alive "$(cat "$DIR/pids/$name")"; then die "$name is already running"; fi
    setsid "$@" >"$DIR/logs/$name.log" 2>&1 </dev/null &
    echo $! >"$DIR/pids/$name"
}

wait_for() {  # NAME SECONDS TEST...: until TEST succeeds; fail with the log if NAME's process died
    local name=$1 secs=$2 deadline=$((SECONDS + $2)); shift 2
    until "$@"; do
        alive "$(cat "$DIR/pids/$name")" || { tail -n 30 "$DIR/logs/$name.log" >&2; die "$name exited while starting"; }
        [ $SECONDS -lt $deadline ] || { tail -n 30 "$DIR/logs/$name.log" >&2; die "$name not ready after ${secs}s"; }
        sleep 0.5
    done
}

node_id() {  # NAME: the Ray node id of the raylet that NAME started
    local raylet
    raylet=$(pgrep -g "$(cat "$DIR/pids/$1")" -x raylet | head -n 1) || return 1
    tr '\0' '\n' <"/proc/$raylet/cmdline" | sed -n 's/^--node_id=//p'
}

node_up() { grep -q "Ray runtime started" "$DIR/logs/$1.log" && [ -n "$(node_id "$1")" ]; }
http_ok() { curl -fs -o /dev/null --max-time 2 "$1"; }

launch_mlflow() {
    mkdir -p "$DIR/mlflow/artifacts"
    launch mlflow mlflow server --host "$HOST" --port "$MLFLOW_PORT" --workers 1 \
        --backend-store-uri "$MLFLOW_BACKEND_URI" --serve-artifacts --artifacts-destination "$DIR/mlflow/artifacts"
}
wait_mlflow() { wait_for mlflow 120 http_ok "http://$HOST:$MLFLOW_PORT/health"; }

launch_node() {  # head | worker-N
    local name=$1 role
    if [ "$name" = head ]; then
        role=(--head --port "$RAY_PORT" --disable-usage-stats)
        if [ -n "$DASHBOARD_PORT" ]; then
            role+=(--include-dashboard true --dashboard-host "$HOST" --dashboard-port "$DASHBOARD_PORT")
        else
            role+=(--include-dashboard false)
        fi
    else
        role=(--address "$HOST:$RAY_PORT")
    fi
    # Separate temp dirs: two nodes on one machine must not share socket paths, and the
    # "ray_current_cluster" file of the default /tmp/ray would make every plain ray.init() on
    # this machine join this cluster.
    launch "$name" ray start --block "${role[@]}" --num-cpus "$CPUS_PER_NODE" \
        --object-store-memory $((OBJECT_STORE_MB * 1024 * 1024)) --temp-dir "$DIR/ray/$name" \
        --dashboard-agent-listen-port "$(free_port)" --metrics-export-port "$(free_port)"
}
wait_node() { wait_for "$1" 120 node_up "$1"; }

write_env() {
    local ids="" f
    for f in "$DIR"/pids/worker-*; do
        if [ -f "$f" ]; then ids+="${ids:+,}$(node_id "$(basename "$f")" || true)"; fi
    done
    cat >"$DIR/cluster.env" <<EOF
LAC_RAY_ADDRESS=$HOST:$RAY_PORT
LAC_TRACKING_URI=http://$HOST:$MLFLOW_PORT
LAC_STORAGE=$DIR/storage
LAC_HEAD_NODE_ID=$(node_id head || true)
LAC_WORKER_NODE_IDS=$ids
RAY_AUTH_MODE=$RAY_AUTH_MODE
WORKERS=$WORKERS
CPUS_PER_NODE=$CPUS_PER_NODE
OBJECT_STORE_MB=$OBJECT_STORE_MB
RAY_PORT=$RAY_PORT
MLFLOW_PORT=$MLFLOW_PORT
DASHBOARD_PORT=$DASHBOARD_PORT
MLFLOW_BACKEND_URI=$MLFLOW_BACKEND_URI
EOF
}

group_pids() {  # PGID: the processes of that group and all their descendants
    ps -eo pid=,ppid=,pgid= | awk -v pg="$1" '
        { pid[NR] = $1; ppid[NR] = $2; if ($3 == pg) keep[$1] = 1 }
        END { do { n = 0; for (i in pid) if (!(pid[i] in keep) && (ppid[i] in keep)) { keep[pid[i]] = 1; n++ } } while (n)
              for (p in keep) print p }'
}

stop_parts() {  # SIG NAME...: signal the groups and their descendants; SIGKILL what is left after $STOP_GRACE s
    local sig=$1 pids="" p name deadline=$((SECONDS + ${STOP_GRACE:-5})); shift
    for name in "$@"; do
        if [ -f "$DIR/pids/$name" ]; then pids+=" $(group_pids "$(cat "$DIR/pids/$name")")"; fi
    done
    # (Ray's processes take their time over SIGTERM; nothing of value lives in them: the sweep's
    # state is in the Tune storage and MLflow.)
    # shellcheck disable=SC2086 # pids: a list of numbers
    if [ -n "${pids// /}" ]; then kill "-$sig" $pids 2>/dev/null || true; fi
    for p in $pids; do
        while alive "$p" && [ $SECONDS -lt $deadline ]; do sleep 0.2; done
        if alive "$p"; then kill -KILL "$p" 2>/dev/null || true; fi
    done
    for name in "$@"; do rm -f "$DIR/pids/$name"; done
}

print_env() {
    cat "$DIR/cluster.env"
    echo
    echo "# a sweep on this cluster:"
    echo "#   RAY_AUTH_MODE=$RAY_AUTH_MODE python sweeps/run.py --space smoke --budget smoke --address $HOST:$RAY_PORT \\"
    echo "#       --tracking-uri http://$HOST:$MLFLOW_PORT --storage $DIR/storage"
    echo "# MLflow UI: http://$HOST:$MLFLOW_PORT${DASHBOARD_PORT:+    Ray dashboard: http://$HOST:$DASHBOARD_PORT}"
    echo "# stop: $0 stop"
}

cmd=${1:-}
part=${2:-}
case "$cmd" in
start)
    if [ -z "$part" ]; then
        for f in "$DIR"/pids/*; do
            if [ -e "$f" ] && alive "$(cat "$f")"; then die "already running under $DIR ($(basename "$f")); stop it first"; fi
        done
        rm -rf "$DIR/pids" "$DIR/cluster.env"
    fi
    load_settings "${part:-fresh}"
    ensure_token
    mkdir -p "$DIR/pids" "$DIR/logs" "$DIR/ray" "$DIR/storage"
    case "$part" in
    "")
        trap '[ $? -eq 0 ] || { echo "cluster.sh: start failed; stopping what it started" >&2; "$0" stop >&2; }' EXIT
        launch_mlflow  # starts while the nodes do
        launch_node head
        wait_node head
        for ((i = 1; i <= WORKERS; i++)); do launch_node "worker-$i"; done
        for ((i = 1; i <= WORKERS; i++)); do wait_node "worker-$i"; done
        wait_mlflow
        write_env
        trap - EXIT
        print_env ;;
    mlflow) launch_mlflow; wait_mlflow ;;
    head | worker-*) launch_node "$part"; wait_node "$part"; write_env ;;
    *) die "start: unknown part '$part' (head, worker-N, mlflow)" ;;
    esac ;;
stop)
    load_settings
    [ -d "$DIR/pids" ] || exit 0
    if [ -n "$part" ]; then stop_parts TERM "$part"; write_env; exit 0; fi
    # shellcheck disable=SC2046 # part names have no spaces
    stop_parts TERM $(ls "$DIR/pids")
    rm -f "$DIR/cluster.env" ;;
kill)
    [ -n "$part" ] || die "kill: which part? (head, worker-N, mlflow)"
    load_settings
    stop_parts KILL "$part"
    write_env ;;
env)
    private_dir
    [ -f "$DIR/cluster.env" ] || die "no cluster under $DIR (run: $0 start)"
    load_settings
    print_env ;;
*)
    sed -n '2,/^set -euo/p' "$0" | sed '$d' >&2
    exit 2 ;;
esac
