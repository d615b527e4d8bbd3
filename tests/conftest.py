"""Test-suite setup: every run re-executes itself inside a private network namespace."""

import os
import pathlib
import sys

import pytest

_ROOT = pathlib.Path(__file__).resolve().parents[1]
# Nothing compiles in a test: the engine is built at set-up, and a signature missing from
# the build is an error here, in this process and in every node the tests start.
os.environ['FPC_ENGINE_STRICT'] = '1'

_WORKER = os.environ.get('PYTEST_XDIST_WORKER', '')
if _WORKER.startswith('gw') and os.environ.get('FPC_NETNS') == '1':
    # xdist's workers share the namespace and name their nodes alike (the same rigs and
    # namespaces in every process): each gets a DDS domain of its own, before any context.
    _base = int(os.environ.get('ROS_DOMAIN_ID', '0'))
    os.environ['ROS_DOMAIN_ID'] = str((_base + 1 + int(_WORKER[2:])) % 102)


@pytest.hookimpl(tryfirst=True)
def pytest_configure(config):
    """Re-exec pytest under scripts/isolated so DDS can never leave the machine."""
    if os.environ.get('FPC_NETNS') == '1':
        return
    capture = config.pluginmanager.getplugin('capturemanager')
    if capture is not None:
        # The exec'd run must write to the real terminal, not pytest's capture files.
        capture.stop_global_capturing()
    argv = [str(_ROOT / 'scripts' / 'isolated'), sys.executable, '-m', 'pytest',
            *config.invocation_params.args]
    sys.stdout.flush()
    sys.stderr.flush()
    os.chdir(config.invocation_params.dir)
    os.execv(argv[0], argv)


def pytest_report_header(config):
    """Show the isolation that ROS tests rely on."""
    return (f"network namespace: private (FPC_NETNS={os.environ.get('FPC_NETNS')}), "
            f"ROS_DOMAIN_ID={os.environ.get('ROS_DOMAIN_ID')}, "
            f"ROS_AUTOMATIC_DISCOVERY_RANGE={os.environ.get('ROS_AUTOMATIC_DISCOVERY_RANGE')}")
