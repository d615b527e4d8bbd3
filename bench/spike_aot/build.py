"""
Build ccm8_cy.py into a native extension with cythonize (the spike's install-time step).

    python bench/spike_aot/build.py [--variant o3|native|native-nofma] [--clean]

Writes _build/<variant>/ccm8_cy.<abi>.so beside this file and prints, as JSON, the
wall time of the cythonize step (.py -> .c), of the C compile and link, and the .so size.
Variants (all `-O3 -g0`, i.e. without the debug info Python's own CFLAGS ask for):

    o3            -O3, the baseline x86-64 ISA (a portable wheel)
    native        -O3 -march=native (GCC then contracts a*b + c into FMA: round-off differs)
    native-nofma  -O3 -march=native -ffp-contract=off (numba's LLVM does not contract)
"""

import argparse
import json
import pathlib
import shutil
import sys
import time

HERE = pathlib.Path(__file__).resolve().parent
SOURCE = HERE / 'ccm8_cy.py'
VARIANTS = {
    'o3': ['-O3', '-g0'],
    'native': ['-O3', '-g0', '-march=native'],
    'native-nofma': ['-O3', '-g0', '-march=native', '-ffp-contract=off'],
}
# Directives: no bounds or wraparound checks, C division (the port never divides by zero
# where numba's would raise: see README), C-level memoryviews without init checks.
DIRECTIVES = {'language_level': 3, 'boundscheck': False, 'wraparound': False,
              'initializedcheck': False, 'cdivision': True}


def build(variant, clean=False):
    """Build one variant; return its timings [s] and the path and size of the .so."""
    from Cython.Build import cythonize
    from setuptools import Extension
    from setuptools.dist import Distribution

    out = HERE / '_build' / variant
    if clean and out.exists():
        shutil.rmtree(out)
    out.mkdir(parents=True, exist_ok=True)
    t0 = time.perf_counter()
    ext = Extension('ccm8_cy', [str(SOURCE)], extra_compile_args=VARIANTS[variant])
    (ext,) = cythonize([ext], build_dir=str(out / 'c'), compiler_directives=DIRECTIVES,
                       force=clean, quiet=True)
    t1 = time.perf_counter()
    dist = Distribution({'name': 'ccm8_cy', 'ext_modules': [ext]})
    cmd = dist.get_command_obj('build_ext')
    cmd.build_lib = str(out)
    cmd.build_temp = str(out / 'tmp')
    cmd.force = clean
    cmd.ensure_finalized()
    cmd.run()
    t2 = time.perf_counter()
    (so,) = out.glob('ccm8_cy*.so')
    return {'variant': variant, 'flags': VARIANTS[variant], 'cythonize_s': t1 - t0,
            'compile_s': t2 - t1, 'total_s': t2 - t0, 'so': str(so),
            'so_bytes': so.stat().st_size}


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[1])
    parser.add_argument('--variant', choices=sorted(VARIANTS), default='o3')
    parser.add_argument('--clean', action='store_true', help='remove the build dir first')
    args = parser.parse_args()
    print(json.dumps(build(args.variant, args.clean)))
    return 0


if __name__ == '__main__':
    sys.exit(main())
