"""Compiles a bench's C (native.py's) once per content with the system's C compiler, into the
temporary directory, and loads it: shared by fil/g071 and fil/bmcu."""

import ctypes
import hashlib
import os
import shutil
import subprocess
import tempfile


def load(source, name):
    """The shared library built from `source`, cached as `<name>-<hash>-<uid>.so`."""
    compiler = shutil.which(os.environ.get("CC", "cc"))
    if not compiler:
        raise RuntimeError("no C compiler (cc) found: the bench needs one for its instruction counter")
    digest = hashlib.sha256(source.encode()).hexdigest()[:12]
    path = os.path.join(tempfile.gettempdir(), f"{name}-{digest}-{os.getuid()}.so")
    if not os.path.exists(path):
        c_file = path[:-3] + f".{os.getpid()}.c"
        with open(c_file, "w") as f:
            f.write(source)
        tmp = f"{path}.{os.getpid()}.tmp"
        subprocess.run([compiler, "-O2", "-shared", "-fPIC", "-o", tmp, c_file], check=True)
        os.replace(tmp, path)
        os.unlink(c_file)
    return ctypes.CDLL(path)
