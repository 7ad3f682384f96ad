"""Builds the optional compiled extensions from src/wholebody/native (the rest of the package
metadata is in pyproject.toml):

- ``wholebody._passive_references``: the passive WBC's per-cycle references around its QP
  (``PassiveWBC(engine="native")``, whose QP is a stack solved by ``_hierarchy_cycle``);
- ``wholebody._hierarchy_cycle``: the rigid-body terms and task rows of ``HierarchyCycle``;
- ``wholebody._cascade``: the cascade of QPs and the single weighted QP, which solve DAQP's QPs
  themselves and hand the other backends' QPs to Python;
- ``wholebody._estimator``: the state estimator's per-cycle numerics
  (``KinematicInertialEKF(engine="native")``);
- ``wholebody._sim_reads``: what the simulator reads from MuJoCo every step (the contact
  wrenches, read from MuJoCo's structs in place with the headers of the ``mujoco`` build
  requirement; the state conversion; the joint-limit watch).

Pinocchio is used header-only (headers and Eigen come from the build requirements ``libpinocchio``
and ``cmeel-eigen``; the cascade and the estimator need Eigen only), so the extensions link no
Pinocchio library and need no run-time path. ``BuildExt`` adds ``-mavx2 -mfma`` when the building machine has AVX2 and
FMA (``WHOLEBODY_PORTABLE=1`` builds for any x86-64 CPU); every extension is built with
``-ffp-contract=off``, so that its results do not depend on where the compiler fuses
multiply-adds. The extensions are optional: without a
C++ compiler, without the headers or pybind11, or with ``WHOLEBODY_NO_NATIVE=1``, the package
installs without them; ``engine="native"`` then raises a clear error and everything else runs in
Python with the same results.
"""

import os
import sys
import tempfile
from pathlib import Path

from setuptools import Extension, setup
from setuptools.command.build_ext import build_ext


def cmeel_include() -> Path | None:
    """The cmeel prefix's include folder that holds both Pinocchio's headers and Eigen's."""
    for entry in sys.path:
        include = Path(entry) / "cmeel.prefix" / "include"
        if (include / "pinocchio").is_dir() and (include / "eigen3").is_dir():
            return include
    return None


def mujoco_include() -> list[str]:
    """[MuJoCo's include folder] from the installed ``mujoco`` package (a build requirement), or
    [] where it is missing: the simulator's compiled reads of MuJoCo's structs are then left
    out (the simulator reads them in Python, with the same results)."""
    try:
        import mujoco
    except ImportError:
        return []
    include = Path(mujoco.__file__).parent / "include"
    return [str(include)] if (include / "mujoco" / "mjdata.h").is_file() else []


def extensions() -> list[Extension]:
    if os.environ.get("WHOLEBODY_NO_NATIVE"):
        return []
    include = cmeel_include()
    if include is None:
        print("wholebody: Pinocchio/Eigen headers not found; building without the native cycle",
              file=sys.stderr)
        return []
    try:
        import pybind11
    except ImportError:  # e.g. --no-build-isolation without pybind11 installed
        print("wholebody: pybind11 not found; building without the native cycle", file=sys.stderr)
        return []

    # no fused multiply-adds formed by the compiler: with -mfma GCC fuses a * b + c where its
    # inlining lets it, which changes with the rest of the translation unit, so that an unrelated
    # edit could move a closed-loop result at round-off; Eigen's explicit FMA kernels are kept
    flags = ["-std=c++17", "-O2", "-g0", "-fvisibility=hidden", "-ffp-contract=off"]
    eigen = [str(include / "eigen3"), pybind11.get_include()]
    mujoco = mujoco_include()
    # Pinocchio's joint variants need larger Boost.MPL limits (its CMake exports these)
    pinocchio_macros = [("BOOST_MPL_LIMIT_LIST_SIZE", "30"), ("BOOST_MPL_LIMIT_VECTOR_SIZE", "30"),
                        ("BOOST_MPL_CFG_NO_PREPROCESSED_HEADERS", None),
                        ("BOOST_FUSION_INVOKE_MAX_ARITY", "12"), ("NDEBUG", None)]
    return [
        Extension(
            "wholebody._passive_references",
            sources=["src/wholebody/native/passive_references.cpp"],
            include_dirs=[str(include)] + eigen,
            define_macros=pinocchio_macros,
            extra_compile_args=flags, language="c++", optional=True),
        Extension(
            "wholebody._hierarchy_cycle",
            sources=["src/wholebody/native/hierarchy_cycle.cpp"],
            include_dirs=[str(include)] + eigen, define_macros=pinocchio_macros,
            extra_compile_args=flags, language="c++", optional=True),
        Extension(  # the cascade: Eigen only
            "wholebody._cascade",
            sources=["src/wholebody/native/cascade.cpp"],
            include_dirs=eigen, define_macros=[("NDEBUG", None)],
            extra_compile_args=flags, language="c++", optional=True),
        Extension(  # the estimator: Eigen only
            "wholebody._estimator",
            sources=["src/wholebody/native/estimator.cpp"],
            include_dirs=eigen, define_macros=[("NDEBUG", None)],
            extra_compile_args=flags, language="c++", optional=True),
        Extension(  # the simulator's reads: pybind11 and MuJoCo's headers (its structs, read in
            # place; no MuJoCo library linked); without fused multiply-adds its sums are those of
            # the Python reference, bit for bit
            "wholebody._sim_reads",
            sources=["src/wholebody/native/sim_reads.cpp"],
            include_dirs=[pybind11.get_include()] + mujoco,
            define_macros=[("NDEBUG", None)] + ([("WHOLEBODY_MUJOCO_HEADERS", None)]
                                                if mujoco else []),
            extra_compile_args=flags, language="c++", optional=True),
    ]


def vector_flags(compiler) -> list[str]:
    """``-mavx2 -mfma`` when the building machine has AVX2 and FMA and the compiler takes them
    (checked by compiling a test file): Eigen's kernels then use 256-bit FMA instructions and the
    compiled cascade runs faster.
    The extensions are built at install on the machine that runs them; set WHOLEBODY_PORTABLE=1
    to build for any x86-64 CPU (e.g. a wheel for other machines)."""
    if os.environ.get("WHOLEBODY_PORTABLE"):
        return []
    try:
        cpu = Path("/proc/cpuinfo").read_text()
    except OSError:  # not Linux: no check of the CPU, no flags
        return []
    words = set(cpu.split())
    if not {"avx2", "fma"} <= words:
        return []
    flags = ["-mavx2", "-mfma"]
    with tempfile.TemporaryDirectory() as tmp:
        source = Path(tmp) / "check.cpp"
        source.write_text("int main() { return 0; }\n")
        try:
            compiler.compile([str(source)], output_dir=tmp, extra_postargs=flags)
        except Exception:  # noqa: BLE001 - any compiler complaint: build without them
            return []
    return flags


class BuildExt(build_ext):
    """build_ext with :func:`vector_flags` added to every extension."""

    def build_extensions(self):
        flags = vector_flags(self.compiler)
        for ext in self.extensions:
            ext.extra_compile_args = list(ext.extra_compile_args or []) + flags
        super().build_extensions()


setup(ext_modules=extensions(), cmdclass={"build_ext": BuildExt})
