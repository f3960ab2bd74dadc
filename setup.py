"""The build of `pip install .` (pyproject.toml): the project's CMake builds the extension
mlfe._mlfe (target mlfe_python) and installs the package with its libmlfe_formats into the
wheel (MLFE_PYTHON_BUNDLE). Needs the Debian packages of scripts/install_deps.sh.

Environment: MLFE_PIP_BUILD_DIR, the CMake build folder (default <clone>/build-pip; kept between
installs, so a second install only relinks; beside build/, so ccache's base_dir rewriting
finds the objects of a normal build); CMAKE_BUILD_PARALLEL_LEVEL, the compile jobs; ccache is
used when installed.
"""
import os
import re
import shutil
import subprocess
import sys

from setuptools import Extension, setup
from setuptools.command.build_ext import build_ext

ROOT = os.path.dirname(os.path.abspath(__file__))


def project_version():
    with open(os.path.join(ROOT, "CMakeLists.txt")) as f:
        return re.search(r"project\(mlfe VERSION ([0-9.]+)", f.read()).group(1)


class CMakeBuild(build_ext):
    def build_extension(self, ext):
        build_dir = os.environ.get("MLFE_PIP_BUILD_DIR", os.path.join(ROOT, "build-pip"))
        if not os.path.exists(os.path.join(build_dir, "CMakeCache.txt")):
            configure = ["cmake", "-S", ROOT, "-B", build_dir, "-DCMAKE_BUILD_TYPE=Release",
                         "-DMLFE_BUILD_TESTS=OFF", "-DMLFE_BUILD_BENCH=OFF"]
            if shutil.which("ninja"):
                configure += ["-G", "Ninja"]
            if shutil.which("ccache"):
                configure += ["-DCMAKE_CXX_COMPILER_LAUNCHER=ccache", "-DCMAKE_C_COMPILER_LAUNCHER=ccache"]
        else:
            configure = ["cmake", "-S", ROOT, "-B", build_dir]
        # The package layout: <prefix>/mlfe/{__init__.py, _mlfe*.so, libmlfe_formats.so, ...}.
        configure += ["-DMLFE_PYTHON_EXECUTABLE=" + sys.executable, "-DMLFE_BUILD_PYTHON=ON",
                      "-DMLFE_PYTHON_BUNDLE=ON", "-DMLFE_PYTHON_INSTALL_DIR=."]
        subprocess.run(configure, check=True)
        build = ["cmake", "--build", build_dir, "--target", "mlfe_python"]
        if "CMAKE_BUILD_PARALLEL_LEVEL" not in os.environ:
            build += ["--parallel", str(os.cpu_count() or 1)]
        subprocess.run(build, check=True)
        prefix = os.path.abspath(self.build_lib)
        subprocess.run(["cmake", "--install", build_dir, "--component", "python", "--prefix", prefix], check=True)
        if not os.path.exists(self.get_ext_fullpath(ext.name)):
            raise RuntimeError("CMake did not install %s" % self.get_ext_fullpath(ext.name))


setup(
    version=project_version(),
    packages=["mlfe"],
    package_dir={"mlfe": "python/mlfe"},
    package_data={"mlfe": ["*.pyi", "py.typed"]},
    ext_modules=[Extension("mlfe._mlfe", sources=[])],
    cmdclass={"build_ext": CMakeBuild},
    zip_safe=False,
)
