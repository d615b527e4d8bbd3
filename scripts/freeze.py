"""
Print `name==version` for every distribution pip installed here, sorted by name.

Run it with the interpreter of the environment to list (`.venv/bin/python
scripts/freeze.py`). Names are normalised as PEP 503 does (lower case, `-`). Left out:
pip itself, the fpc_gripper checkout, and the metadata-only `*.egg-info` directories
that the ROS 2 wheels carry inside themselves (`rclpy`, `std_msgs`, ...): no installer
put those there on their own, and no index serves them.
"""

import importlib.metadata
import re

LEFT_OUT = frozenset({'pip', 'fpc-gripper'})


def canonical(name):
    """Return the PEP 503 form of a distribution name."""
    return re.sub(r'[-_.]+', '-', name).lower()


def pins():
    """Return the sorted `name==version` lines of the installed distributions."""
    found = {}
    for dist in importlib.metadata.distributions():
        # An installer (pip) writes INSTALLER into every .dist-info; embedded egg-info has none.
        if dist.read_text('INSTALLER') is None:
            continue
        name = canonical(dist.metadata['Name'])
        if name not in LEFT_OUT:
            found.setdefault(name, dist.version)
    return [f'{name}=={version}' for name, version in sorted(found.items())]


if __name__ == '__main__':
    print('\n'.join(pins()))
