"""Which OpenGL library draws `irring view`'s offscreen picture: OSMesa or EGL.

Chosen and checked without importing MuJoCo: ``import mujoco`` loads the library
``MUJOCO_GL`` names and fails deep inside PyOpenGL (``'NoneType' object has no attribute
'glGetError'``) when it is not installed.
"""

from __future__ import annotations

import ctypes.util
import os

from ..errors import UsageError

# backend -> (the library ctypes looks for, the Debian packages that install it)
LIBRARIES = {"osmesa": ("OSMesa", "libosmesa6"), "egl": ("EGL", "libegl1 libgl1-mesa-dri")}
NAMES = {"osmesa": "OSMesa", "egl": "EGL"}


def install_hint(backend: str) -> str:
    """'apt install …' for a backend, as the Debian packages that install it."""
    return f"Debian: apt install {LIBRARIES[backend][1]}"


def check_chosen_library() -> None:
    """Raise UsageError when ``MUJOCO_GL`` names egl or osmesa and that library is not
    installed (MuJoCo cannot even be imported then), saying what to install or set."""
    choice = os.environ.get("MUJOCO_GL", "").strip().lower()
    if choice not in LIBRARIES or ctypes.util.find_library(LIBRARIES[choice][0]):
        return
    other = "egl" if choice == "osmesa" else "osmesa"
    fix = f"install it ({install_hint(choice)})"
    if ctypes.util.find_library(LIBRARIES[other][0]):
        fix = f"{NAMES[other]} is: set MUJOCO_GL={other} or unset it, or {fix}"
    raise UsageError(f"MUJOCO_GL={choice}: the {NAMES[choice]} library is not installed; "
                     f"{fix}")


def context_failed(backend: str, exc: BaseException) -> RuntimeError:
    """The error for a backend whose library is there but cannot make an offscreen context
    (an EGL without a driver for a display-less device, say), with what to do instead."""
    if backend == "egl":
        instead = (f"OSMesa needs no driver: install it ({install_hint('osmesa')}) and set "
                   "MUJOCO_GL=osmesa")
    else:
        instead = f"try EGL: set MUJOCO_GL=egl ({install_hint('egl')})"
    return RuntimeError(f"{NAMES[backend]} cannot make an offscreen OpenGL context here "
                        f"({type(exc).__name__}: {exc}); {instead}")


def gl_backend() -> str:
    """'egl' or 'osmesa': MUJOCO_GL if it names one, else the first whose library loads.
    Raises RuntimeError saying what to install when neither is there."""
    choice = os.environ.get("MUJOCO_GL", "").strip().lower()
    if choice in LIBRARIES:
        return choice
    # OSMesa first: all software, one library, nothing else to match (EGL also needs a
    # vendor library and a driver, and a half-installed EGL fails only once in use)
    if ctypes.util.find_library("OSMesa"):
        return "osmesa"
    if ctypes.util.find_library("EGL"):
        return "egl"
    raise RuntimeError("no headless OpenGL library found for an offscreen picture: install "
                       "EGL or OSMesa (Debian: apt install libegl1 libgl1-mesa-dri, or "
                       "apt install libosmesa6)")
