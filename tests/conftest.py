"""Test-suite setup: every run re-executes itself inside a private network namespace."""

import os
import pathlib
import sys

_ROOT = pathlib.Path(__file__).resolve().parents[1]


def _ensure_isolated():
    """Re-exec pytest under scripts/isolated so DDS can never leave the machine."""
    if os.environ.get('FPC_NETNS') == '1':
        return
    argv = [str(_ROOT / 'scripts' / 'isolated'), sys.executable, '-m', 'pytest', *sys.argv[1:]]
    sys.stdout.flush()
    sys.stderr.flush()
    os.execv(argv[0], argv)


_ensure_isolated()


def pytest_report_header(config):
    """Show the isolation that ROS tests rely on."""
    return (f"network namespace: private (FPC_NETNS={os.environ.get('FPC_NETNS')}), "
            f"ROS_DOMAIN_ID={os.environ.get('ROS_DOMAIN_ID')}, "
            f"ROS_AUTOMATIC_DISCOVERY_RANGE={os.environ.get('ROS_AUTOMATIC_DISCOVERY_RANGE')}")
