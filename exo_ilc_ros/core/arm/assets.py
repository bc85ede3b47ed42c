"""The files a viewer fetches to draw an arm (its URDF's meshes): a ``package://``,
``file://`` or relative URI to a file, only inside the allowed roots.

A viewer (the Foxglove app's 3D panel) asks the live view's server for each mesh its URDF
names (the protocol's ``fetchAsset``). :class:`AssetResolver` answers with the file's bytes:

* ``package://name/rest``: ``rest`` in the package's share directory, found the ROS way
  (``ament_index_python``, where installed), else in the share directory of a Python wheel
  that carries it (``<site-packages>/cmeel.prefix/share/name``, as the PyPI package
  ``example-robot-data`` installs the meshes of the shipped Panda and UR5), else, for this
  package, beside its shipped configs;
* ``file:///abs/path`` and a relative path (relative to the URDF's directory).

Anything else is refused (None): a file outside every allowed root (the share directories
found, the URDF's directory), after resolving ``..`` and symlinks, so no URI reaches a file
elsewhere on the machine. No ROS import: ``ament_index_python`` is optional.
"""

from __future__ import annotations

import contextlib
import site
import sys
import sysconfig
from collections.abc import Iterable
from pathlib import Path
from urllib.parse import unquote, urlparse

from ..params.config import config_dir
from ..params.urdf_xml import UrdfError, resolve_package_uri

PACKAGE = "exo_ilc_ros"
MAX_ASSET_BYTES = 256 * 1024 * 1024
"""A file larger than this is not sent (a mesh is a few MB)."""


def _site_dirs() -> list[Path]:
    """Where installed wheels are (this interpreter's site-packages)."""
    found: list[str] = [sysconfig.get_paths()["purelib"], sysconfig.get_paths()["platlib"]]
    with contextlib.suppress(AttributeError):  # a virtualenv's old site.py has none
        found += site.getsitepackages()
    found += [p for p in sys.path if p.endswith("site-packages")]
    out: list[Path] = []
    for entry in found:
        path = Path(entry)
        if path.is_dir() and path not in out:
            out.append(path)
    return out


def package_share(package: str) -> Path | None:
    """The share directory of ``package``: ament's, a wheel's ``cmeel.prefix/share``, or
    (this package) the directory holding the shipped ``config/`` and ``urdf/``."""
    try:
        return resolve_package_uri(f"package://{package}/").resolve()
    except UrdfError:
        pass
    for site_dir in _site_dirs():
        candidate = site_dir / "cmeel.prefix" / "share" / package
        if candidate.is_dir():
            return candidate.resolve()
    if package == PACKAGE:
        return config_dir().parent.resolve()
    return None


class AssetResolver:
    """Resolves the asset URIs of one URDF (``urdf_file``: its path, for relative URIs; None
    for a URDF built in memory) to bytes, within the allowed roots."""

    def __init__(self, urdf_file: Path | None = None,
                 packages: Iterable[str] = ()) -> None:
        self.base = urdf_file.resolve().parent if urdf_file is not None else None
        self.shares: dict[str, Path | None] = {}
        for package in packages:
            self.share(package)

    def share(self, package: str) -> Path | None:
        """``package``'s share directory (looked up once)."""
        if package not in self.shares:
            self.shares[package] = package_share(package)
        return self.shares[package]

    def roots(self) -> list[Path]:
        """Every directory a file may be served from."""
        out = [p for p in self.shares.values() if p is not None]
        return out + ([self.base] if self.base is not None else [])

    def path(self, uri: str) -> Path | None:
        """The file ``uri`` names, or None (unknown scheme or package, outside the roots,
        not a file)."""
        if not uri or "\x00" in uri:
            return None
        if uri.startswith("package://"):
            package, _, rest = uri[len("package://"):].partition("/")
            share = self.share(package) if package and package not in (".", "..") else None
            if share is None:
                return None
            candidate = share / unquote(rest)
        elif uri.startswith("file://"):
            parsed = urlparse(uri)
            if parsed.netloc not in ("", "localhost"):
                return None
            candidate = Path(unquote(parsed.path))
        elif "://" in uri or self.base is None:
            return None
        else:
            candidate = self.base / unquote(uri)
        try:
            resolved = candidate.resolve(strict=True)  # follows every symlink
        except (OSError, RuntimeError):
            return None
        if not resolved.is_file():
            return None
        if not any(resolved.is_relative_to(root) for root in self.roots()):
            return None
        return resolved

    def fetch(self, uri: str) -> bytes | None:
        """The bytes of the file ``uri`` names, or None (refused or not found)."""
        found = self.path(uri)
        if found is None:
            return None
        try:
            if found.stat().st_size > MAX_ASSET_BYTES:
                return None
            return found.read_bytes()
        except OSError:
            return None


def urdf_packages(urdf: str) -> list[str]:
    """The packages a URDF's ``package://`` URIs name, in order of first use."""
    out: list[str] = []
    start = 0
    while (at := urdf.find("package://", start)) >= 0:
        name = urdf[at + len("package://"):].split("/", 1)[0]
        if name and name not in out:
            out.append(name)
        start = at + 1
    return out
