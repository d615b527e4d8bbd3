"""Nodes started on an invalid config exit 2 with one line on stderr, and never stay up."""

import json
import os
import subprocess
import sys
import textwrap

import pytest

pytestmark = pytest.mark.ros

MIB = 1 << 20

# Runs each case's main in turn in one process (an import of the package costs seconds),
# with fd 2 sent to the case's own file, and prints the exit codes as JSON.
_CHILD = textwrap.dedent("""
    import importlib, json, os, sys
    codes = []
    for module, args, err in json.loads(sys.argv[1]):
        main = importlib.import_module('fpc_gripper.nodes.' + module).main
        saved = os.dup(2)
        with open(err, 'wb') as stream:
            os.dup2(stream.fileno(), 2)
            try:
                codes.append(main(args=['node', '--ros-args', *args]))
            finally:
                os.dup2(saved, 2)
    # This process's own peak (VmHWM): a wait4 rusage would also count the pages of the
    # parent it was forked from, which in a long test session is gigabytes.
    with open('/proc/self/status') as status:
        peak_kib = next(int(line.split()[1]) for line in status if line.startswith('VmHWM:'))
    print(json.dumps([codes, peak_kib]))
""")


def _bomb():
    lines = ['a0: &a0 ["lol", "lol", "lol", "lol", "lol", "lol", "lol", "lol", "lol", "lol"]']
    for i in range(1, 10):
        lines.append(f'a{i}: &a{i} [' + ', '.join([f'*a{i - 1}'] * 10) + ']')
    return '\n'.join(lines) + '\nfingers: *a9\n'


CASES = {
    # name: (node module, {file: text}, parameters, words of the one line)
    'bridge-alias-bomb': ('regulator_bridge', {'bomb': _bomb()},
                          ['gripper_config:={bomb}'], ['bomb.yaml', 'more than 64 aliases']),
    'bridge-modbus-map': ('regulator_bridge',
                          {'map': 'connection: {port: 0x1F6}\nchannels: []\n'},
                          ['backend:=modbus', 'modbus_config:={map}'],
                          ['map.yaml: connection.port', 'not a plain decimal']),
    'model-node-design': ('model_node',
                          {'gripper': 'fingers:\n  - name: f0\n  - name: f1\n'
                                      '    design: {Lx: -0.11}\n'},
                          ['gripper_config:={gripper}'],
                          ['gripper.yaml: fingers[1].design.Lx: must be > 0 [m], got -0.11']),
}


def test_invalid_configs_exit_2_with_one_line_and_no_memory_blow_up(tmp_path):
    runs = []
    for name, (module, files, parameters, _) in CASES.items():
        paths = {}
        for stem, text in files.items():
            paths[stem] = tmp_path / f'{stem}.yaml'
            paths[stem].write_text(text)
        args = []
        for parameter in parameters:
            args += ['-p', parameter.format(**{k: str(v) for k, v in paths.items()})]
        runs.append((module, args, str(tmp_path / f'{name}.stderr')))
    process = subprocess.run([sys.executable, '-c', _CHILD, json.dumps(runs)],
                             capture_output=True, text=True, timeout=300,
                             env=dict(os.environ, RCUTILS_COLORIZED_OUTPUT='0'))
    out, err = process.stdout, process.stderr
    assert process.returncode == 0, err
    codes, peak_kib = json.loads(out.strip().splitlines()[-1])
    for (name, (_, _, _, words)), code in zip(CASES.items(), codes):
        lines = [line for line in (tmp_path / f'{name}.stderr').read_text().splitlines()
                 if line.strip()]
        assert code == 2, (name, lines)
        assert len(lines) == 1, (name, lines)
        assert 'Traceback' not in lines[0], (name, lines)
        assert all(word in lines[0] for word in words), (name, lines[0])
    # The alias bomb is refused unread: the process stays the size of an idle node.
    assert peak_kib * 1024 < 1024 * MIB, peak_kib
