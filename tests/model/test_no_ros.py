"""The physics core imports and solves with numpy and scipy alone."""

import subprocess
import sys
import textwrap


def test_model_imports_without_ros():
    code = textwrap.dedent("""
        import sys
        class Block:
            def find_spec(self, name, path=None, target=None):
                root = name.split('.')[0]
                if root in {'rclpy', 'std_msgs', 'sensor_msgs', 'geometry_msgs', 'nav_msgs',
                            'rosidl_runtime_py', 'rcl_interfaces', 'yaml'}:
                    raise ImportError('blocked: ' + name)
        sys.meta_path.insert(0, Block())
        import fpc_gripper.model as m
        r = m.CCMSolver(m.ActuatorDesign.paper(0.25), 4).solve(1e5)
        assert r.success
        assert not any(k.split('.')[0] == 'rclpy' for k in sys.modules)
        print('ok')
    """)
    out = subprocess.run([sys.executable, '-c', code], capture_output=True, text=True,
                         timeout=120)
    assert out.returncode == 0, out.stderr
    assert out.stdout.strip() == 'ok'
