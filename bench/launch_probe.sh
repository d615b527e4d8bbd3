#!/usr/bin/env bash
# A developer check of a read-only colcon install under ros2 launch (needs the ros2cli harness; not for CI):
#   ../shared/tools/first_run.sh readonly "bash src/fpc_gripper/bench/launch_probe.sh"  (from the project root)
# Twice: launch, send a first goal, time the first /markers, then a terminal's Ctrl-C twice, 30 ms apart.
set -u
for round in 1 2; do
LOG=/tmp/ro_launch$round.log
start=$(date +%s.%N)
setsid ros2 launch fpc_gripper gripper.launch.py > $LOG 2>&1 &
LP=$!
timeout 60 ros2 topic echo --once /markers visualization_msgs/msg/MarkerArray > /tmp/ro_marker$round.txt 2>&1 &
EP=$!
# A user's first goal: an aperture of 80 mm, repeated at 5 Hz until the first /markers (one
# message can reach the recorder, which subscribes too, before the controller has matched).
timeout 60 ros2 topic pub -r 5 /aperture_command std_msgs/msg/Float64 '{data: 0.08}' > /tmp/ro_pub$round.txt 2>&1 &
PP=$!
wait $EP; erc=$?
seen=$(echo "$(date +%s.%N) - $start" | bc)
kill $PP 2>/dev/null; wait $PP 2>/dev/null
echo "round $round: first /markers after $seen s (echo rc $erc, $(wc -l < /tmp/ro_marker$round.txt) lines; goals published: $(grep -c '^publishing #' /tmp/ro_pub$round.txt))"
ros2 topic list > /tmp/ro_topics$round.log 2>&1
sleep 2
t0=$(date +%s.%N)
kill -INT -$LP; sleep 0.03; kill -INT -$LP
wait $LP; rc=$?
echo "round $round: launch exit $rc after $(echo "$(date +%s.%N) - $t0" | bc) s"
grep -E 'process has (finished|died)|ERROR|exit code|Traceback' $LOG
done
echo "files written into HOME: $(find $HOME -type f | wc -l)"
