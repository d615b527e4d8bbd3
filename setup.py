"""Setup script for the fpc_gripper ament_python package."""

from glob import glob
import os
import subprocess
import sys

from setuptools import find_packages, setup
from setuptools.command.build_py import build_py

package_name = 'fpc_gripper'


class BuildWithEngine(build_py):
    """build_py, then the compiled engine into the built package (pip install, colcon build)."""

    def run(self):
        super().run()
        if self.dry_run or getattr(self, 'editable_mode', False) \
                or os.environ.get('FPC_SKIP_ENGINE_BUILD'):
            # An editable install builds in place: scripts/setup.sh runs the build itself.
            return
        try:
            import numba  # noqa: F401
        except ImportError:
            print('fpc_gripper: numba is not importable here, so the engine is not built: '
                  'run `python -m fpc_gripper.model.build` after the install (or install '
                  'with --no-build-isolation)', file=sys.stderr)
            return
        # In the built copy, so that its sources are the ones stamped; a build copied in
        # with the package data (a source tree already set up) is kept when current.
        subprocess.run([sys.executable, '-m', 'fpc_gripper.model.build', '--if-stale'],
                       cwd=self.build_lib, check=True)


setup(
    name=package_name,
    version='0.1.0',
    packages=find_packages(exclude=['tests', 'tests.*', 'bench']),
    package_data={'fpc_gripper': ['data/*.json', 'data/*.xml', 'model/compiled/*']},
    cmdclass={'build_py': BuildWithEngine},
    data_files=[
        ('share/ament_index/resource_index/packages', ['resource/' + package_name]),
        ('share/' + package_name, ['package.xml']),
        ('share/' + package_name + '/msg_configs', glob('msg_configs/*.yaml')),
        ('share/' + package_name + '/launch', glob('launch/*.launch.py')),
        ('share/' + package_name + '/config', glob('config/*.yaml')),
        ('share/' + package_name + '/urdf', glob('urdf/*.urdf')),
        ('share/' + package_name + '/rviz', glob('rviz/*.rviz')),
    ],
    install_requires=['setuptools', 'numpy', 'scipy', 'numba', 'PyYAML', 'pandas', 'tqdm'],
    # fpc-design: sweeps on a Dask cluster (--scheduler), parquet tables (--format parquet).
    # continuum: the offline finite-element rung (fpc_gripper/model/continuum/).
    extras_require={'dask': ['dask', 'distributed'], 'parquet': ['pyarrow'],
                    'continuum': ['scikit-fem']},
    zip_safe=True,
    maintainer='fpc_gripper developers',
    maintainer_email='dev@fpc-gripper.invalid',
    description='CCM model and ROS 2 nodes for a fluidic prestressed composite gripper.',
    license='Apache-2.0',
    tests_require=['pytest'],
    entry_points={
        'console_scripts': [
            'model_node = fpc_gripper.nodes.entry_points:model_node',
            'regulator_bridge = fpc_gripper.nodes.entry_points:regulator_bridge',
            'mcap_recorder = fpc_gripper.nodes.entry_points:mcap_recorder',
            'gripper_controller = fpc_gripper.nodes.entry_points:gripper_controller',
            'gripper = fpc_gripper.nodes.entry_points:gripper',
            'virtual_object = fpc_gripper.nodes.entry_points:virtual_object',
            'gripper_demo = fpc_gripper.nodes.entry_points:gripper_demo',
            'fpc-mcap = fpc_gripper.io.cli:main',
            'fpc-calibrate = fpc_gripper.calibration.cli:main',
            'fpc-grasp = fpc_gripper.grasp.cli:main',
            'fpc-design = fpc_gripper.design.cli:main',
        ],
    },
)
