"""mcap_recorder whose executor stalls once, on purpose, right after its first message."""

# Run as a process, exactly as `mcap_recorder` runs (run_node, SIGINT to stop):
#   python tests/io/stalled_recorder.py STALL_S --ros-args -p output_path:=... ...
# One timer of the node's own sleeps STALL_S seconds in the executor thread as soon as a
# message has been received, and logs 'stalled' when it wakes: meanwhile nothing is taken
# from the middleware, as when a CPU hog or a burst holds the executor.

import sys
import time

from fpc_gripper.nodes.mcap_recorder import McapRecorder
from fpc_gripper.nodes.runner import run_node


def stalled_recorder(stall_s):
    """Build the recorder with its one-shot stall."""
    node = McapRecorder()
    state = {'timer': None}

    def stall():
        if not node.received:
            return
        node.destroy_timer(state['timer'])
        time.sleep(stall_s)
        node.get_logger().info(f'stalled the executor for {stall_s:g} s')

    state['timer'] = node.create_timer(0.01, stall)
    return node


def main(argv=None):
    """Run the stalled recorder until SIGINT or SIGTERM."""
    argv = sys.argv if argv is None else argv
    stall_s = float(argv[1])
    return run_node(lambda: stalled_recorder(stall_s), 'mcap_recorder', argv)


if __name__ == '__main__':
    sys.exit(main())
