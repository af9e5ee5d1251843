"""The FMU archive: zip checks, the extraction cache, the binary for this platform.

An FMU is refused (:class:`FmuInputError`, naming the file and the entry) when it is not a zip
archive, when an entry would escape the extraction folder (absolute paths, ``..``, links), or when it
has no binary for this platform. It is extracted once per content (cached by its SHA-256).
"""

from __future__ import annotations

import os
import shutil
import stat
import tempfile
import zipfile
from pathlib import Path, PurePosixPath
from typing import Sequence

from calib.errors import InputError


class FmuInputError(InputError):
    """Bad FMU or mapping (an :class:`InputError`)."""


# ----------------------------------------------------------------------------- archive
def check_archive(path: Path) -> list[str]:
    """Entry names of an FMU archive, refusing anything that is not a safe zip.

    Raises
    ------
    InputError
        Missing file, not a zip archive, an entry that would be written outside the
        extraction folder (absolute, drive letter, ``..``, a symbolic link), no
        ``modelDescription.xml``.
    """
    src = str(path)
    if not path.is_file():
        raise FmuInputError("FMU file not found", src)
    if not zipfile.is_zipfile(path):
        raise FmuInputError("not an FMU: the file is not a zip archive (an FMU is a zip holding modelDescription.xml, "
                            "binaries/ and resources/)", src)
    with zipfile.ZipFile(path) as z:
        infos = z.infolist()
    names = []
    for info in infos:
        name = info.filename
        posix = name.replace("\\", "/")
        parts = PurePosixPath(posix).parts
        unsafe = (posix.startswith("/") or (len(posix) > 1 and posix[1] == ":") or ".." in parts)
        is_link = stat.S_ISLNK(info.external_attr >> 16)
        if unsafe or is_link:
            what = "a symbolic link" if is_link else "a path outside the extraction folder"
            raise FmuInputError(f"zip entry {name!r} is {what}; refused (an FMU's entries must stay inside the folder "
                                "it is extracted to)", src, field=name)
        names.append(posix)
    if "modelDescription.xml" not in names:
        raise FmuInputError("not an FMU: the zip archive has no modelDescription.xml at its top level", src,
                            field="modelDescription.xml")
    return names


def extract_once(path: Path, sha: str) -> str:
    """Extract a checked FMU into the cache (``$CALIB_CACHE/fmu_extract/<sha>``), once."""
    from calib.fmu.build import cache_dir

    root = cache_dir().parent / "fmu_extract"
    target = root / sha[:24]
    if (target / ".complete").is_file():
        return str(target)
    root.mkdir(parents=True, exist_ok=True)
    tmp = Path(tempfile.mkdtemp(prefix=f"{sha[:12]}-", dir=root))
    try:
        with zipfile.ZipFile(path) as z:
            for info in z.infolist():
                dest = tmp / info.filename.replace("\\", "/")
                if info.is_dir():
                    dest.mkdir(parents=True, exist_ok=True)
                    continue
                dest.parent.mkdir(parents=True, exist_ok=True)
                with z.open(info) as fin, open(dest, "wb") as fout:
                    shutil.copyfileobj(fin, fout)
        (tmp / ".complete").write_text(str(path))
        try:
            os.replace(tmp, target)
        except OSError:        # another process extracted it meanwhile
            shutil.rmtree(tmp, ignore_errors=True)
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise
    return str(target)


def platform_binary(md, names: Sequence[str], src: str) -> str:
    """Path inside the archive of the shared library for this platform (checked)."""
    import fmpy
    from fmpy import sharedLibraryExtension

    ident = md.coSimulation.modelIdentifier
    plat = fmpy.platform_tuple if md.fmiVersion.startswith("3") else fmpy.platform
    want = f"binaries/{plat}/{ident}{sharedLibraryExtension}"
    if want not in names:
        have = sorted({n.split("/")[1] for n in names if n.startswith("binaries/") and n.count("/") >= 2})
        raise FmuInputError(f"no binary for this platform: expected {want}; the FMU has binaries for "
                            f"{', '.join(have) or 'no platform'} (ask the vendor for a {plat} build, or "
                            "rebuild from sources)", src, field=want)
    return want
