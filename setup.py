"""The build's one addition to pyproject.toml: the numeric kernels, compiled by Cython.

A kernel is an ordinary Python module with a `.pxd` beside it that gives its C types; compiled
or not, it computes the same bits. A machine without a C compiler installs the package all the
same (`optional`), and the kernels run as Python; CI checks that they were compiled. After
editing a kernel, `pip install -e .` again (tests/test_compiled_kernels.py says when it is stale).
"""

from pathlib import Path

from Cython.Build import cythonize
from setuptools import Extension, setup

KERNELS = sorted(path.with_suffix(".py").as_posix() for path in Path("hapticop").rglob("*.pxd"))

setup(ext_modules=cythonize(
    [Extension(path[:-3].replace("/", "."), [path], optional=True,
               extra_compile_args=["-ffp-contract=off"])  # no fused multiply-add: Python's bits
     for path in KERNELS],
    compiler_directives={"language_level": 3},
))
