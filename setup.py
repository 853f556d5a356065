"""Builds the compiled kernels with the package (`pip install .`): the twin's (bwsd/twin/csrc)
and the relaxation's step (bwsd/relax/csrc).

Everything else about the package is in pyproject.toml. Both kernels are C11 with GNU
extensions (the twin's uses 128-bit integers), built with floating-point contraction off (a
fused multiply-add would change the float filters' error bounds, docs/twin.md, "Exactness")
and with -Wall -Wextra -Wconversion, of which the compiler has nothing to say
(tests/test_build.py).
A build without three.js in bwsd/web/node_modules (`npm ci --prefix bwsd/web` first) warns:
its live preview page would say that three.js is missing instead of drawing the preform.
"""

from __future__ import annotations

import sys
from pathlib import Path

from setuptools import Extension, setup
from setuptools.command.build_ext import build_ext
from setuptools.errors import CCompilerError, CompileError, ExecError, PlatformError

SOURCES = sorted(str(p) for p in Path("bwsd/twin/csrc").glob("*.c"))
THREE = Path("bwsd/web/node_modules/three/build/three.module.js")
FLAGS = [
    "-std=gnu11",
    "-O2",
    "-ffp-contract=off",
    "-fno-fast-math",
    "-fvisibility=hidden",
    "-Wall",
    "-Wextra",
    "-Wconversion",
]

NO_COMPILER = """
bwsd: cannot build its twin kernel (bwsd/twin/csrc), a C extension.
It needs a C compiler (gcc or clang) and the Python headers. On Debian or Ubuntu:
    sudo apt-get install gcc python3-dev
then run the install again. ({error})
"""


NO_THREE = """
bwsd: warning: three.js is not in bwsd/web/node_modules: the live preview page of this build
cannot draw the preform, and says so. Run `npm ci --prefix bwsd/web` before building.
"""


class BuildKernel(build_ext):
    """build_ext that turns a missing compiler into one clear message."""

    def run(self) -> None:
        try:
            super().run()
        except (CCompilerError, CompileError, ExecError, PlatformError, OSError) as exc:
            sys.stderr.write(NO_COMPILER.format(error=exc))
            raise SystemExit(1) from exc

    def build_extension(self, ext: Extension) -> None:
        try:
            super().build_extension(ext)
        except (CCompilerError, CompileError, ExecError, PlatformError, OSError) as exc:
            sys.stderr.write(NO_COMPILER.format(error=exc))
            raise SystemExit(1) from exc


if not THREE.is_file():
    sys.stderr.write(NO_THREE)

setup(
    ext_modules=[
        Extension(
            "bwsd.twin._kernel",
            sources=SOURCES,
            depends=sorted(str(p) for p in Path("bwsd/twin/csrc").glob("*.h")),
            extra_compile_args=FLAGS,
        ),
        Extension(
            "bwsd.relax._step",
            sources=["bwsd/relax/csrc/step.c"],
            extra_compile_args=FLAGS,
        ),
    ],
    cmdclass={"build_ext": BuildKernel},
)
