#!/usr/bin/env bash
# End-to-end proof of the ROS 2 test harness, in a private network namespace (needs root for
# `unshare -n`):
#   Zenoh side: tests/ros2/zenoh_peer_probe.py (eclipse-zenoh, client) publishes CDR
#               sensor_msgs/JointState on KEY/joint_states at 50 Hz and prints what
#               arrives on KEY/joint_commands;
#   router:     robobus-ros2-router (zenoh-plugin-ros2dds), the probe's only Zenoh peer;
#   ROS side:   tests/ros2/ros_node.py (rclpy, Fast DDS) receives 5 JointState and then
#               publishes std_msgs/Float64MultiArray [0.1, 0.2] on joint_commands.
# KEY is the router's --namespace followed by the node's namespace (both empty by default:
# keys joint_states and joint_commands). Exit 0 only if both directions worked: the node got
# 5 JointState with the probe's names and values, and the probe decoded [0.1, 0.2].
#
# Usage: tests/ros2/check_pipeline.sh [--router-namespace NS] [--node-namespace NS]
#                                     [--domain N] [--timeout S] [--keep DIR]
#   --timeout S how long the ROS node waits for its 5 JointState (default 60)
#   --keep DIR  keeps every process's output in DIR (default: a temporary directory,
#               removed at the end; on failure it is kept and the tails of its files printed).
# Runs scripts/bridge/ros2-setup first (apt packages, venv, router build), unless
# ROBOBUS_ROS2_ROUTER and ROBOBUS_ROS2_PYTHON name a built router and the venv's python.
set -euo pipefail
cd "$(dirname "$0")/../.."

router_ns="" node_ns="" domain=0 timeout=60 keep=""
inside=0
while [ $# -gt 0 ]; do
    case "$1" in
        --router-namespace) router_ns=${2:?--router-namespace needs a value}; shift 2 ;;
        --node-namespace) node_ns=${2:?--node-namespace needs a value}; shift 2 ;;
        --domain) domain=${2:?--domain needs a value}; shift 2 ;;
        --timeout) timeout=${2:?--timeout needs a value}; shift 2 ;;
        --keep) keep=${2:?--keep needs a value}; shift 2 ;;
        --inside) inside=1; shift ;;
        *) sed -n '/^# Usage/,/^# ROBOBUS/p' "$0" | sed 's/^# \{0,1\}//' >&2; exit 2 ;;
    esac
done

if [ "$inside" = 0 ]; then
    if [ -z "${ROBOBUS_ROS2_ROUTER:-}" ] || [ -z "${ROBOBUS_ROS2_PYTHON:-}" ]; then
        setup=$(scripts/bridge/ros2-setup)
        ROBOBUS_ROS2_ROUTER=$(sed -n 's/^router=//p' <<<"$setup")
        ROBOBUS_ROS2_PYTHON=$(sed -n 's/^python=//p' <<<"$setup")
    fi
    export ROBOBUS_ROS2_ROUTER ROBOBUS_ROS2_PYTHON
    args=(--domain "$domain" --timeout "$timeout")
    [ -n "$router_ns" ] && args+=(--router-namespace "$router_ns")
    [ -n "$node_ns" ] && args+=(--node-namespace "$node_ns")
    [ -n "$keep" ] && args+=(--keep "$keep")
    exec unshare -n "$0" --inside "${args[@]}"
fi

# ---- inside the private network namespace ----
router=$ROBOBUS_ROS2_ROUTER
python=$ROBOBUS_ROS2_PYTHON
ip link set lo up
# Multicast on lo, for any DDS participant that still uses it (SUBNET range).
ip route add 224.0.0.0/4 dev lo
# The router's Cyclone DDS discovers over unicast to localhost only (LOCALHOST range, no
# multicast); Fast DDS must use the same range, or the two never discover each other.
export ROS_DOMAIN_ID=$domain ROS_DISTRO=${ROS_DISTRO:-jazzy} ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST
export PYTHONUNBUFFERED=1
endpoint=tcp/127.0.0.1:7450

# The Zenoh key prefix: the plugin prefixes its namespace to the node's full topic names.
prefix=""
for ns in "$router_ns" "$node_ns"; do
    ns=${ns#/}; ns=${ns%/}
    [ -n "$ns" ] && prefix="$prefix$ns/"
done
node_args=()
[ -n "$node_ns" ] && node_args+=(--namespace "$node_ns")
router_args=(--listen "$endpoint" --domain "$domain")
[ -n "$router_ns" ] && router_args+=(--namespace "$router_ns")

if [ -n "$keep" ]; then
    work=$keep
    mkdir -p "$work"
else
    work=$(mktemp -d /tmp/ros2-check.XXXXXX)
fi
pids=()
status=1
# shellcheck disable=SC2317 # called by the EXIT trap
cleanup() {
    local pid
    for pid in "${pids[@]}"; do
        kill -TERM "$pid" 2>/dev/null || true
    done
    for pid in "${pids[@]}"; do
        wait "$pid" 2>/dev/null || true
    done
    if [ "$status" != 0 ]; then
        for f in "$work"/*; do
            echo "---- $f" >&2
            tail -n 30 "$f" >&2
        done
    elif [ -z "$keep" ]; then
        rm -rf "$work"
    fi
}
trap cleanup EXIT
t0=$EPOCHREALTIME
elapsed() { awk -v now="$EPOCHREALTIME" -v t0="$t0" 'BEGIN { printf "%.1f", now - t0 }'; }

"$router" "${router_args[@]}" >"$work/router.out" 2>"$work/router.err" </dev/null &
pids+=($!)
for _ in $(seq 300); do
    grep -q '^router: ready$' "$work/router.out" && break
    kill -0 "${pids[0]}" 2>/dev/null || { echo "check: the router exited" >&2; exit 1; }
    sleep 0.1
done
grep -q '^router: ready$' "$work/router.out" || { echo "check: the router was not ready within 30 s" >&2; exit 1; }
echo "check: router ready after $(elapsed) s (keys: ${prefix}joint_states, ${prefix}joint_commands)"

"$python" tests/ros2/zenoh_peer_probe.py --connect "$endpoint" --rate 50 --seconds 120 \
    --key "${prefix}joint_states" --command-key "${prefix}joint_commands" \
    >"$work/probe.out" 2>"$work/probe.err" </dev/null &
pids+=($!)

node_status=0
"$python" tests/ros2/ros_node.py "${node_args[@]}" --expect 5 --command 0.1,0.2 \
    --rate 20 --seconds 2 --timeout "$timeout" >"$work/node.out" 2>"$work/node.err" </dev/null || node_status=$?
echo "check: ros_node exited $node_status after $(elapsed) s"
sed -n 's/^ros_node: first/check: ros_node: first/p' "$work/node.err"

# The last commands may still be on their way: give the probe a moment, then stop it.
for _ in $(seq 20); do
    grep -q '"type": "command"' "$work/probe.out" && break
    sleep 0.1
done
sleep 0.3
kill -TERM "${pids[1]}" 2>/dev/null || true
wait "${pids[1]}" 2>/dev/null || true

# Both directions, checked from the JSON lines.
if "$python" - "$work/node.out" "$work/probe.out" <<'EOF'
import json, sys
node = [json.loads(l) for l in open(sys.argv[1]) if l.startswith("{")]
probe = [json.loads(l) for l in open(sys.argv[2]) if l.startswith("{")]
states = [m for m in node if m["type"] == "joint_state"]
published = [m["count"] for m in node if m["type"] == "published"]
commands = [m for m in probe if m["type"] == "command"]
summary = [m for m in probe if m["type"] == "probe"]
ok = True
def check(cond, what):
    global ok
    print(("ok:   " if cond else "FAIL: ") + what)
    ok = ok and cond
check(len(states) == 5, f"ROS node received {len(states)} of 5 JointState from Zenoh")
check(bool(states) and all(s["names"] == ["joint1", "joint2"] and s["velocity"] == [0.25, 0.25]
          and s["effort"] == [1.0, 1.0] and s["position"][1] == -1.25
          and s["position"][0] % 0.5 == 0 and s["stamp"][0] > 0 for s in states),
      "JointState names, position, velocity, effort and stamp as the probe sent them")
check(bool(published) and published[0] > 0, f"ROS node published {published[0] if published else 0} commands")
good = [c for c in commands if c.get("data") == [0.1, 0.2]]
check(bool(good), f"Zenoh probe decoded {len(good)} Float64MultiArray [0.1, 0.2] "
      f"(of {len(commands)} received, {published[0] if published else 0} published)")
if commands:
    print("first command payload:", commands[0]["hex"])
if summary:
    print(f"probe published {summary[0]['published']} JointState samples")
sys.exit(0 if ok else 1)
EOF
then
    status=0
fi
echo "check: $([ $status = 0 ] && echo passed || echo FAILED) after $(elapsed) s"
exit $status
