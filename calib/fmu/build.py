"""Build the rotor FMUs (variants A and B) from the C sources in ``fmu_models/``.

``build_fmu("A")`` stages an FMU folder (generated ``modelDescription.xml``, the
sources, generated ``fmu_variables.h``, ``resources/`` written from a calib rotor),
compiles the shared library with fmpy's CMake project and the FMI headers that ship
with fmpy (``fmpy/c-code``), links libm, and zips the result. Builds are cached by a
hash of everything that goes in (sources, specs, resources, this generator's Python,
fmpy's build files, sanitizer flags) in
``$CALIB_CACHE/fmus`` (default ``<repo>/.calib_cache/fmus``); binaries are never
written into the source tree.

Command line (wired as ``calib fmu build``)::

    python -m calib.fmu.build [--variant A|B|all] [--rotor NAME] [--out DIR] [--force]
"""

from __future__ import annotations

import argparse
import hashlib
import os
import shutil
import subprocess
import sys
import tempfile
import uuid
import zipfile
from pathlib import Path

from calib.corrections import CorrectionGrid
from calib.errors import CalibError, InputError
from calib.fmu import model_description as md
from calib.fmu import variant_spec
from calib.fmu.resources import default_grid, rotor_facts, write_resources

REPO_ROOT = Path(__file__).resolve().parents[2]
FMU_MODELS = REPO_ROOT / "fmu_models"
CORE_DIR = FMU_MODELS / "core"
VARIANTS = {"A": "variant_a", "B": "variant_b"}
BUILD_FORMAT = "1"  # bump when the staging layout changes

INSTALL_HINT = ("install them and make sure they are on PATH, e.g. on Debian/Ubuntu "
                "`sudo apt-get install build-essential cmake`, on Fedora `sudo dnf install gcc cmake`, "
                "on macOS `xcode-select --install && brew install cmake`, or `pip install cmake` for CMake")


class FmuBuildError(CalibError, RuntimeError):
    """The FMU could not be built (missing tools, compiler errors)."""


def cache_dir() -> Path:
    """Where built FMUs are cached: ``$CALIB_CACHE/fmus`` or ``<repo>/.calib_cache/fmus``."""
    root = os.environ.get("CALIB_CACHE")
    return (Path(root) if root else REPO_ROOT / ".calib_cache") / "fmus"


def variant_dir(variant: str) -> Path:
    """``fmu_models/variant_a`` for ``"A"`` (case-insensitive)."""
    key = str(variant).upper()
    if key not in VARIANTS:
        raise InputError(f"unknown FMU variant {variant!r}; valid: {', '.join(VARIANTS)}", "build_fmu",
                         field="variant")
    return FMU_MODELS / VARIANTS[key]


def mapping_path(variant: str) -> Path:
    """The declarative mapping file of a variant (``fmu_models/<variant>/mapping.toml``)."""
    return variant_dir(variant) / "mapping.toml"


def find_tools() -> tuple[str, str]:
    """Absolute paths of CMake and a C compiler.

    Raises
    ------
    FmuBuildError
        Naming what is missing and how to install it.
    """
    cmake = shutil.which("cmake")
    cc_env = os.environ.get("CC")
    cc = shutil.which(cc_env) if cc_env else None
    cc = cc or shutil.which("cc") or shutil.which("gcc") or shutil.which("clang")
    missing = [name for name, found in (("CMake (>= 3.15)", cmake), ("a C compiler (gcc or clang)", cc))
               if not found]
    if missing:
        raise FmuBuildError(f"building the rotor FMU needs {' and '.join(missing)}, not found on PATH; "
                            + INSTALL_HINT)
    return cmake, cc


def _source_files(variant: str) -> list[Path]:
    vdir = variant_dir(variant)
    files = sorted(CORE_DIR.glob("*.c")) + sorted(CORE_DIR.glob("*.h"))
    files += sorted(vdir.glob("*.c")) + sorted(vdir.glob("*.h")) + [vdir / "variables.toml"]
    return files


def _generator_files() -> list[Path]:
    """The Python that writes the model description, C table and resources (part of the key)."""
    from calib.fmu import resources
    return [Path(__file__), Path(variant_spec.__file__), Path(md.__file__), Path(resources.__file__)]


def _fmpy_build_files() -> list[Path]:
    import fmpy
    c_code = Path(fmpy.__file__).parent / "c-code"
    return sorted(c_code.iterdir()) + [Path(fmpy.__file__).parent / "build.py"]


def _hash(paths: list[Path], extra: list[bytes]) -> str:
    h = hashlib.sha256()
    h.update(BUILD_FORMAT.encode())
    for p in paths:
        h.update(p.name.encode())
        h.update(p.read_bytes())
    for e in extra:
        h.update(e)
    return h.hexdigest()


def _run(cmd: list[str], what: str):
    proc = subprocess.run(cmd, capture_output=True, text=True)
    if proc.returncode != 0:
        tail = "\n".join((proc.stdout + "\n" + proc.stderr).strip().splitlines()[-40:])
        raise FmuBuildError(f"{what} failed (exit code {proc.returncode}): {' '.join(cmd)}\n{tail}")


#: Compiler and linker flags of a sanitized build (``build_fmu(..., sanitize=True)``):
#: AddressSanitizer and UndefinedBehaviorSanitizer (plus float-to-int overflow, which GCC
#: leaves out of ``undefined``), every report fatal.
SANITIZE_FLAGS = (
    "-fsanitize=address,undefined,float-cast-overflow "   # GCC: float-cast-overflow is not in `undefined`
    "-fno-sanitize-recover=undefined,float-cast-overflow -fno-omit-frame-pointer -g")


def build_fmu(variant: str, rotor=None, grid: CorrectionGrid | None = None, out_dir=None,
              force: bool = False, sanitize: bool = False) -> Path:
    """Build (or fetch from the cache) the rotor FMU of one variant.

    Parameters
    ----------
    variant : {"A", "B"}
        A: FMI 2.0, scalar correction nodes, SI units. B: FMI 3.0, array corrections,
        kW / kN·m, other names and azimuth convention (see ``fmu_models/README.md``).
    rotor : Rotor, optional
        Rotor whose geometry and polars go into ``resources/``; default
        ``calib.rotor.library.load_rotor("nrel5mw")``.
    grid : CorrectionGrid, optional
        Correction node grid; default :func:`calib.fmu.resources.default_grid`
        (α nodes -10..20 deg every 5 deg, η nodes 0.2..1.0 every 0.2).
    out_dir : str or Path, optional
        Also copy the FMU (and its ``mapping.toml``) there.
    force : bool
        Rebuild even if the cache holds this build.
    sanitize : bool
        Compile with ``-fsanitize=address,undefined -fno-sanitize-recover=undefined``
        (:data:`SANITIZE_FLAGS`), cached under a separate key (suffix ``-sanitize``). The
        binary needs the sanitizer runtime loaded first: a Python process that loads it
        must run with ``LD_PRELOAD=$(cc -print-file-name=libasan.so)`` (and usually
        ``ASAN_OPTIONS=detect_leaks=0``), see :func:`sanitizer_environment`.

    Returns
    -------
    Path
        The ``.fmu`` file (in ``out_dir`` if given, else in the cache).

    Raises
    ------
    FmuBuildError
        No compiler / CMake (says what to install), or a compiler error (with its output).
    InputError
        Unknown variant, bad spec or rotor data.
    """
    vdir = variant_dir(variant)
    key = str(variant).upper()
    if rotor is None:
        from calib.rotor.library import load_rotor
        rotor = load_rotor("nrel5mw")
    grid = grid or default_grid()
    cmake, cc = find_tools()

    with tempfile.TemporaryDirectory(prefix="calib_fmu_res_") as tmp:
        facts = write_resources(rotor, grid, Path(tmp))
        resource_bytes = [(Path(tmp) / n).read_bytes() for n in ("rotor.dat", "correction_grid.json")]
    spec_args = dict(n_nodes=facts["n_nodes"], alpha_nodes=list(grid.alpha_nodes_deg),
                     eta_nodes=list(grid.eta_nodes), out_radius=list(facts["out_radius"]),
                     out_eta=list(facts["out_eta"]), rotor_facts=rotor_facts(rotor))
    core_ids = variant_spec.core_variable_ids(CORE_DIR / "rotor_core.h")
    spec = variant_spec.load_spec(vdir / "variables.toml", core_ids, **spec_args)
    flavour = [SANITIZE_FLAGS.encode()] if sanitize else []
    digest = _hash(_source_files(key) + _generator_files() + _fmpy_build_files(),
                   resource_bytes + [Path(cc).name.encode()] + flavour)
    token = "{" + str(uuid.UUID(digest[:32])) + "}"
    suffix = "-sanitize" if sanitize else ""
    target_dir = cache_dir() / f"{spec.model_identifier}-{rotor.name}-{digest[:16]}{suffix}"
    fmu_path = target_dir / f"{spec.model_identifier}.fmu"

    if force or not fmu_path.is_file():
        target_dir.mkdir(parents=True, exist_ok=True)
        with tempfile.TemporaryDirectory(prefix="build_", dir=target_dir) as work:
            _build_into(Path(work), fmu_path, spec, token, rotor, grid, key, cmake, sanitize)
    if out_dir is None:
        return fmu_path
    out_dir = Path(out_dir).resolve()
    out_dir.mkdir(parents=True, exist_ok=True)
    dest = out_dir / fmu_path.name
    shutil.copy2(fmu_path, dest)
    shutil.copy2(vdir / "mapping.toml", out_dir / f"{spec.model_identifier}.mapping.toml")
    return dest


def sanitizer_environment(base: dict | None = None) -> dict:
    """Environment for a process that loads a sanitized FMU (``build_fmu(..., sanitize=True)``).

    A sanitized shared library ``dlopen``'ed by an unsanitized executable (CPython) needs
    the ASan runtime loaded first: ``LD_PRELOAD`` gets ``cc -print-file-name=libasan.so``.
    Leak detection is off (CPython itself keeps memory until exit), reports abort the process.

    Raises
    ------
    FmuBuildError
        The compiler has no ASan runtime.
    """
    _, cc = find_tools()
    lib = subprocess.run([cc, "-print-file-name=libasan.so"], capture_output=True, text=True).stdout.strip()
    if not lib or not Path(lib).is_file():
        raise FmuBuildError(f"{cc} has no AddressSanitizer runtime (libasan.so); install it "
                            "(Debian/Ubuntu: the libasan package of your gcc, e.g. `apt-get install libasan8`)")
    env = dict(os.environ if base is None else base)
    env["LD_PRELOAD"] = lib
    env["ASAN_OPTIONS"] = "detect_leaks=0:abort_on_error=1"
    env["UBSAN_OPTIONS"] = "print_stacktrace=1:halt_on_error=1"
    return env


def _write_cmake_cache(build_dir: Path, spec, stage: Path, sources: list[str], fmi3: bool,
                       sanitize: bool = False):
    """Pre-seed the cache of fmpy's CMake project (``fmpy/c-code/CMakeLists.txt``).

    Same entries as :func:`fmpy.build.create_cmake_settings` (which needs a build
    description inside the model description for FMI 2), plus libm and warnings.
    """
    import fmpy
    target = stage / "binaries" / (fmpy.platform_tuple if fmi3 else fmpy.platform)
    entries = {
        "CMAKE_BUILD_TYPE:STRING": "Release",
        "FMI_MODEL_IDENTIFIER:STRING": spec.model_identifier,
        "FMI_INCLUDE_DIRS:STRING": (stage / "sources").resolve().as_posix(),
        "FMI_SOURCES:STRING": ";".join((stage / "sources" / s).resolve().as_posix() for s in sources),
        "FMI_DEFINITIONS:STRING": "",
        "FMI_TARGET_DIR:STRING": target.resolve().as_posix(),
        "FMI_ALL_WARNINGS:BOOL": "ON",
        "CMAKE_C_STANDARD_LIBRARIES:STRING": "-lm",   # link libm
        "CMAKE_C_STANDARD:STRING": "99",
    }
    if sanitize:
        entries["CMAKE_C_FLAGS:STRING"] = SANITIZE_FLAGS
        entries["CMAKE_SHARED_LINKER_FLAGS:STRING"] = SANITIZE_FLAGS
    (build_dir / "CMakeCache.txt").write_text("".join(f"{k}={v}\n" for k, v in entries.items()))


def _build_into(work: Path, fmu_path: Path, spec: variant_spec.VariantSpec, token: str, rotor, grid, key: str,
                cmake: str, sanitize: bool = False):
    import fmpy

    stage = work / "fmu"
    sources = stage / "sources"
    sources.mkdir(parents=True)
    write_resources(rotor, grid, stage / "resources")
    names = []
    for src in _source_files(key):
        if src.suffix in (".c", ".h"):
            shutil.copy2(src, sources / src.name)
            if src.suffix == ".c":
                names.append(src.name)
    (sources / "fmu_variables.h").write_text(md.render_c_table(spec, token))
    (sources / "buildDescription.xml").write_text(md.render_build_description(spec, names))
    render = md.render_fmi2 if spec.fmi_version == "2.0" else md.render_fmi3
    (stage / "modelDescription.xml").write_text(render(spec, token))

    build_dir = work / "cmake-build"
    build_dir.mkdir()
    _write_cmake_cache(build_dir, spec, stage, names, fmi3=spec.fmi_version == "3.0", sanitize=sanitize)
    c_code = Path(fmpy.__file__).parent / "c-code"
    _run([cmake, "-S", str(c_code.resolve()), "-B", str(build_dir.resolve())], "CMake configure")
    _run([cmake, "--build", str(build_dir.resolve()), "--target", "install", "--config", "Release"],
         "CMake build")

    binaries = list((stage / "binaries").rglob("*.so")) + list((stage / "binaries").rglob("*.dylib")) \
        + list((stage / "binaries").rglob("*.dll"))
    if not binaries:
        raise FmuBuildError(f"the build produced no shared library under {stage / 'binaries'}")
    tmp_zip = work / (fmu_path.name + ".part")     # in this build's own folder: concurrent builds never share it
    with zipfile.ZipFile(tmp_zip, "w", zipfile.ZIP_DEFLATED) as zf:
        for path in sorted(stage.rglob("*")):
            rel = path.relative_to(stage).as_posix()
            if path.is_dir() or rel.startswith("sources/"):
                continue  # ship binary and resources only, as a vendor would
            zf.write(path, rel)
    os.replace(tmp_zip, fmu_path)


BUILD_DESCRIPTION = ("Build the bundled turbine FMUs (variant A: FMI 2.0; variant B: FMI 3.0) from the C sources "
                     "in fmu_models/ with the FMI headers and CMake project that ship with fmpy; results are "
                     "cached by source hash in .calib_cache/. Prints the path of each FMU and its mapping file.")


def add_build_arguments(parser: argparse.ArgumentParser) -> argparse.ArgumentParser:
    """The options of ``calib fmu build`` (shared by this module's ``main`` and ``calib.cli``)."""
    parser.add_argument("--variant", default="all", choices=["A", "B", "a", "b", "all"],
                        help="which FMU to build: A, B or all (default: all)")
    parser.add_argument("--rotor", default="nrel5mw",
                        help="embedded rotor whose geometry and polars go into the FMU's resources "
                             "(see 'calib rotors'; default: nrel5mw)")
    parser.add_argument("--out", default=None, help="also copy the FMUs and their mapping files to this folder")
    parser.add_argument("--force", action="store_true", help="rebuild even if a cached build exists")
    return parser


def run_build(args) -> int:
    """Build what ``args`` (from :func:`add_build_arguments`) asks for; 0 on success, 1 on error."""
    from calib.rotor.library import load_rotor
    try:
        rotor = load_rotor(args.rotor)
        variants = list(VARIANTS) if args.variant == "all" else [args.variant.upper()]
        for v in variants:
            path = build_fmu(v, rotor=rotor, out_dir=args.out, force=args.force)
            print(f"variant {v}: {path}")
            print(f"  mapping: {mapping_path(v)}")
    except (CalibError, OSError) as exc:
        print(f"calib fmu build: error: {exc}", file=sys.stderr)
        return 1
    return 0


def main(argv: list[str] | None = None) -> int:
    """``calib fmu build``: build the rotor FMUs and print where they are."""
    parser = add_build_arguments(argparse.ArgumentParser(prog="calib fmu build", description=BUILD_DESCRIPTION))
    return run_build(parser.parse_args(argv))

if __name__ == "__main__":
    sys.exit(main())
