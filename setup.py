"""Builds the extension tetstream._core and the `tetstream` command with the project's CMake
(pyproject.toml has the metadata).

    python3 -m venv --system-site-packages venv     # Debian's numpy, setuptools and wheel
    venv/bin/pip install --no-build-isolation .    # offline

The CMake build directory is build-python/ (TETSTREAM_BUILD_DIR overrides it, e.g. an
existing build/); the module is built for the interpreter running pip. The binary goes
into the package (tetstream/_bin/tetstream), and the console script `tetstream`
(tetstream._cli) runs it, so a pip-only user has the whole command line. Needs pybind11
(pybind11-dev) and the Python headers (python3-dev): scripts/setup.sh installs them.
"""
import glob
import os
import shutil
import subprocess
import sys

from setuptools import Extension, setup
from setuptools.command.build_ext import build_ext

ROOT = os.path.dirname(os.path.abspath(__file__))


class CMakeBuild(build_ext):
    def build_extension(self, ext):
        build = os.environ.get("TETSTREAM_BUILD_DIR") or os.path.join(ROOT, "build-python")
        configure = ["cmake", "-S", ROOT, "-B", build, "-DTETSTREAM_PYTHON=ON"]
        # The interpreter, unless the build directory has this one already under another
        # name (a venv's python is a link to the system's): reconfiguring it with the
        # venv's path would tie the build to a directory that may go away.
        if os.path.realpath(_cached(build, "Python3_EXECUTABLE") or "") != os.path.realpath(sys.executable):
            configure.append(f"-DPython3_EXECUTABLE={sys.executable}")
        if not os.path.exists(os.path.join(build, "CMakeCache.txt")):
            # a new build directory: Release, and no test suite (an existing one, e.g.
            # TETSTREAM_BUILD_DIR=build, keeps its own settings)
            configure += ["-DCMAKE_BUILD_TYPE=Release", "-DTETSTREAM_BUILD_TESTS=OFF"]
            if shutil.which("ninja"):
                configure += ["-G", "Ninja"]
        subprocess.check_call(configure)
        jobs = os.environ.get("CMAKE_BUILD_PARALLEL_LEVEL") or str(os.cpu_count() or 1)
        subprocess.check_call(["cmake", "--build", build, "--target", "tetstream_python", "tetstream", "-j", jobs])
        built = glob.glob(os.path.join(build, "python", "tetstream", "_core*.so"))
        if not built:
            sys.exit("tetstream: the extension was not built (is pybind11-dev installed? see the CMake output)")
        dest = self.get_ext_fullpath(ext.name)
        os.makedirs(os.path.dirname(dest), exist_ok=True)
        shutil.copyfile(built[0], dest)
        # The command line, as package data that the console script runs.
        binary = os.path.join(os.path.dirname(dest), "_bin", "tetstream")
        os.makedirs(os.path.dirname(binary), exist_ok=True)
        shutil.copyfile(os.path.join(build, "tools", "tetstream"), binary)
        os.chmod(binary, 0o755)


def _cached(build, name):
    """A variable's value in BUILD/CMakeCache.txt, or None."""
    try:
        with open(os.path.join(build, "CMakeCache.txt")) as f:
            for line in f:
                if line.startswith(name + ":"):
                    return line.split("=", 1)[1].strip()
    except OSError:
        pass
    return None


setup(ext_modules=[Extension("tetstream._core", sources=[])], cmdclass={"build_ext": CMakeBuild},
      # setuptools' own staging, kept out of the CMake build directory build/
      options={"build": {"build_base": os.path.join("build-python", "setuptools")}})
