"""The `tetstream` console script of a pip-installed package: runs the command-line binary
that setup.py put into the package (tetstream/_bin/tetstream), or, from a build tree
(PYTHONPATH=BUILD/python), the one CMake built (BUILD/tools/tetstream)."""
import os
import sys


def binary() -> str:
    here = os.path.dirname(os.path.abspath(__file__))
    for candidate in (os.path.join(here, "_bin", "tetstream"), os.path.join(here, "..", "..", "tools", "tetstream")):
        if os.access(candidate, os.X_OK):
            return os.path.realpath(candidate)
    raise FileNotFoundError(f"tetstream: the command-line binary is not in {here}/_bin (reinstall the package)")


def main() -> None:
    try:
        path = binary()
    except FileNotFoundError as e:
        sys.stderr.write(f"{e}\n")
        sys.exit(3)
    os.execv(path, [path] + sys.argv[1:])


if __name__ == "__main__":
    main()
