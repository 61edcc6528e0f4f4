"""The basin kernel's machine code, loaded without numba.

numba's import and the first dispatch of its cached kernel take about 0.4 s of a basin run's
start-up on one core (numba's typing and target registries), a quarter of a 1000 x 1000 grid's
whole run. The machine code itself is 40 kB. Here the classifier ``compiled._classify`` is
compiled once by numba as a C-callable function over raw pointers (``numba.cfunc`` of
``compiled.classify_entry``, which allocates nothing), its object code is saved, and later
runs load it with llvmlite (numba's own LLVM binding, installed with it; public API) in about
0.01 s and call it through ctypes, which releases the GIL, so that tiles run in threads as
with numba. Loaded this way it is the same machine code as numba's own, so the same bits.

The symbols the code refers to are bound to the addresses numba binds them to
(``numba.core.base._load_global_helpers``, ``externals``, ``runtime.nrt``): numba's C helper
libraries (``_helperlib``, ``_dynfunc``, ``_nrt_python``, loaded from numba's installation as
extension modules without importing numba), the C library's math functions through
``_helperlib``'s table, CPython's exceptions and functions. The kernel calls none of them on
its way (only ``cos`` and ``sin`` of ``_launch``); the rest is numba's error path.

What keeps a wrong piece of machine code from running:

- the object is keyed (``cache_key``) by the kernel's sources, numba's and llvmlite's
  versions, Python's, the host's triple, CPU name and features, and every ``NUMBA_*``
  variable: code compiled for another CPU, or by another numba, is never loaded;
- its SHA-256 is checked before it is loaded (a truncated or altered file is not);
- every symbol it refers to (read from the checked object's own symbol table) must resolve
  here, or it is not loaded (LLVM would leave an unresolved one empty, and the first call
  would crash);
- before it is first used, a fresh Python process without numba loads it and classifies a
  test grid, and its outcomes and impact counts must equal numba's, bit for bit; otherwise
  the key is marked unusable and numba's dispatcher runs, now and in later runs;
- anything failing on the way (a broken llvmlite, a damaged file, no home directory) makes
  ``classifier`` return None: numba's dispatcher or numpy runs, as without this module.

``BOUNCE_KERNEL=numba`` keeps to numba's dispatcher; ``BOUNCE_KERNEL=numpy`` to numpy.
"""

from __future__ import annotations

import ctypes
import functools
import hashlib
import importlib.machinery
import importlib.util
import json
import os
import struct
import subprocess
import sys
import tempfile
import threading
from pathlib import Path
from typing import Any, Callable

import numpy as np

from .kernel_arrays import classify_scratch, kernel_inputs, solver_constants
from .params import FixedPoint, ModelParams

#: the entry's arguments (``compiled.classify_entry``): (ctypes type, numba type name)
_ENTRY_ARGS = (
    ("p", "float64"),  # theta0[n]
    ("p", "float64"),  # v0[n]
    ("p", "float64"),  # the constants (kernel_arrays)
    ("i", "int64"),  # n
    ("i", "int64"),  # max_iterations
    ("i", "int64"),  # max_steps
    ("p", "int8"),  # outcome[n]
    ("p", "int16"),  # iterations[n]
    ("p", "int64"),  # idx[n]
    ("p", "float64"),  # work[12, n]
    ("p", "int64"),  # pos[n]
)
#: the files whose text is the kernel (the key changes with any of them)
_KERNEL_SOURCES = ("compiled.py", "kernel_arrays.py", "trig.py", "impact.py", "native.py")
#: the verification grid's model (Fig. 4's) and a second one with another racket
_CHECK_MODELS = ((0.5, 9.81, 0.3, 0.92), (0.7, 9.81, 0.2, 0.6))


def _package_dir(name: str) -> Path | None:
    """The directory of an installed top-level package, found without importing it."""
    spec = importlib.util.find_spec(name)
    if spec is None or spec.origin is None:
        return None
    return Path(spec.origin).parent


def cache_dirs() -> list[Path]:
    """Where the object is kept, in the order it is looked for: ``$NUMBA_CACHE_DIR/bounce``
    where numba's cache is redirected; else this package's ``__pycache__`` (as numba's own
    cache) and the user's cache directory, for installations that cannot be written."""
    numba_cache = os.environ.get("NUMBA_CACHE_DIR")
    if numba_cache:
        return [Path(numba_cache) / "bounce"]
    found = [Path(__file__).parent / "__pycache__"]
    try:  # a user without a home directory (a container's bare uid): the package's only
        found.append(Path(os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache")
                     / "bounce")
    except RuntimeError:
        pass
    return found


def cache_key() -> str | None:
    """The object's key (hex SHA-256), or None where numba or llvmlite is not installed.
    Imports llvmlite's binding (about 0.03 s) for the host's CPU name and features."""
    numba_dir, llvmlite_dir = _package_dir("numba"), _package_dir("llvmlite")
    if numba_dir is None or llvmlite_dir is None:
        return None
    import llvmlite.binding as ll

    digest = hashlib.sha256()
    for part in (sys.version, sys.platform, ll.get_process_triple(), ll.get_host_cpu_name(),
                 ll.get_host_cpu_features().flatten(),
                 repr(sorted((k, v) for k, v in os.environ.items() if k.startswith("NUMBA_")))):
        digest.update(part.encode() + b"\0")
    # numba's settings may also come from this file in the working directory (numba.core.config)
    settings_file = Path(".numba_config.yaml")
    digest.update(settings_file.read_bytes() if settings_file.is_file() else b"")
    digest.update(b"\0")
    here = Path(__file__).parent
    for path in [here / name for name in _KERNEL_SOURCES] + [
            numba_dir / "_version.py", llvmlite_dir / "_version.py"]:
        digest.update(path.read_bytes() + b"\0")
    return digest.hexdigest()


def _paths(directory: Path, key: str) -> tuple[Path, Path, Path]:
    """(object, metadata, unusable marker) of a key in a cache directory."""
    stem = directory / f"classify-{key[:24]}"
    return stem.with_suffix(".o"), stem.with_suffix(".json"), stem.with_suffix(".unusable")


def _extension(numba_dir: Path, dotted: str) -> Any:
    """One of numba's C extension modules, loaded from its file without importing numba
    (extension modules need no package; their addresses are numba's own)."""
    relative = dotted.split(".")[1:]
    folder = numba_dir.joinpath(*relative[:-1])
    for suffix in importlib.machinery.EXTENSION_SUFFIXES:
        path = folder / (relative[-1] + suffix)
        if path.exists():
            loader = importlib.machinery.ExtensionFileLoader(dotted, str(path))
            spec = importlib.util.spec_from_file_location(dotted, path, loader=loader)
            assert spec is not None
            module = importlib.util.module_from_spec(spec)
            return module
    raise ImportError(f"{dotted}: no extension file in {folder}")


@functools.lru_cache(maxsize=1)
def _process() -> ctypes.CDLL:
    """The symbols of this process (CPython's and the libraries it loaded: ``dlsym`` of the
    default scope, where LLVM looks for what numba does not bind)."""
    return ctypes.CDLL(None)


def _symbol_addresses(names: list[str]) -> dict[str, int] | None:
    """The address of each symbol the object refers to, bound as numba binds it; None if
    any cannot be resolved."""
    numba_dir = _package_dir("numba")
    if numba_dir is None:
        return None
    import builtins

    helpers: dict[str, int] = {}
    runtime: dict[str, int] = {}
    if any(not n.startswith(("Py", "_Py")) for n in names):
        for dotted in ("numba._helperlib", "numba._dynfunc"):
            helpers.update(_extension(numba_dir, dotted).c_helpers)
        nrt = _extension(numba_dir, "numba.core.runtime._nrt_python")
        nrt.memsys_use_cpython_allocator()  # as numba.core.runtime.nrt does on import
        runtime = {(k if k.startswith("_") else "NRT_" + k): v for k, v in nrt.c_helpers.items()}
    addresses = {}
    for name in names:
        exception = getattr(builtins, name[len("PyExc_"):], None)
        if name.startswith("numba_") and name[len("numba_"):] in helpers:
            addresses[name] = helpers[name[len("numba_"):]]
        elif name in runtime:
            addresses[name] = runtime[name]
        elif name == "_Py_NoneStruct":
            addresses[name] = id(None)
        elif (name.startswith("PyExc_") and isinstance(exception, type)
              and issubclass(exception, BaseException)):
            addresses[name] = id(exception)
        elif name in helpers:  # the C library's math functions (numba's ``externals``)
            addresses[name] = helpers[name]
        else:  # CPython's functions, the C library's: where LLVM itself finds them
            try:
                address = ctypes.cast(getattr(_process(), name), ctypes.c_void_p).value
            except AttributeError:
                return None
            if not address:
                return None
            addresses[name] = address
    return addresses


def undefined_symbols(code: bytes) -> list[str] | None:
    """The names an object file refers to and does not define (its symbol table's entries
    in no section), or None where it is not a 64-bit little-endian ELF file (Linux): other
    systems keep to numba's dispatcher."""
    if code[:4] != b"\x7fELF" or code[4] != 2 or code[5] != 1:
        return None
    section_offset, = struct.unpack_from("<Q", code, 0x28)
    entry_size, count = struct.unpack_from("<HH", code, 0x3A)
    sections = [struct.unpack_from("<IIQQQQIIQQ", code, section_offset + i * entry_size)
                for i in range(count)]
    names: set[str] = set()
    for _, kind, _, _, offset, size, link, _, _, symbol_size in sections:
        if kind != 2:  # SHT_SYMTAB
            continue
        strings = sections[link][4]
        for at in range(offset, offset + size, symbol_size):
            name_at, _, _, section = struct.unpack_from("<IBBH", code, at)
            if section == 0 and name_at:  # SHN_UNDEF
                end = code.index(b"\0", strings + name_at)
                names.add(code[strings + name_at:end].decode())
    return sorted(names)


class NativeClassifier:
    """``compiled._classify``'s machine code, callable on numpy arrays (``__call__``)."""

    def __init__(self, address: int, engine: Any):
        self._engine = engine  # owns the code: kept alive as long as the function
        kinds = {"p": ctypes.c_void_p, "i": ctypes.c_int64}
        self._function = ctypes.CFUNCTYPE(None, *(kinds[k] for k, _ in _ENTRY_ARGS))(address)

    def __call__(self, theta0: np.ndarray, v0: np.ndarray, constants: np.ndarray,
                 max_iterations: int, max_steps: int) -> tuple[np.ndarray, np.ndarray]:
        """(outcome int8, iterations int16) of contiguous float64 arrays (``_classify``)."""
        n = theta0.size
        outcome, iterations, (idx, work, pos) = classify_scratch(n)
        self._function(theta0.ctypes.data, v0.ctypes.data, constants.ctypes.data, n,
                       max_iterations, max_steps, outcome.ctypes.data, iterations.ctypes.data,
                       idx.ctypes.data, work.ctypes.data, pos.ctypes.data)
        return outcome, iterations


def _load_object(obj_path: Path, meta: dict) -> NativeClassifier | None:
    """The classifier from an object file and its metadata, or None (see the module)."""
    if not (isinstance(meta.get("symbol"), str) and meta["symbol"].isascii()
            and isinstance(meta.get("undefined"), list)):
        return None
    code = obj_path.read_bytes()
    if hashlib.sha256(code).hexdigest() != meta.get("sha256"):
        return None
    undefined = undefined_symbols(code)  # from the checked bytes, not the metadata's word
    if undefined is None or undefined != meta["undefined"]:
        return None
    addresses = _symbol_addresses(undefined)
    if addresses is None:
        return None
    import llvmlite.binding as ll

    ll.initialize_native_target()
    ll.initialize_native_asmprinter()
    for name, address in addresses.items():
        ll.add_symbol(name, address)
    target = ll.Target.from_default_triple()
    machine = target.create_target_machine(cpu=ll.get_host_cpu_name(), opt=0,
                                           codemodel="jitdefault")
    engine = ll.create_mcjit_compiler(ll.parse_assembly(""), machine)
    engine.add_object_file(ll.ObjectFileRef.from_data(code))
    engine.finalize_object()
    address = engine.get_function_address(meta["symbol"])
    return NativeClassifier(address, engine) if address else None


def classifier() -> NativeClassifier | None:
    """The classifier's machine code saved by ``build_classifier``, loaded without numba, or
    None (not built yet for this key, marked unusable, ``BOUNCE_KERNEL`` not ``auto``, or
    anything on the way failing: a broken llvmlite, a damaged file, no home directory; the
    caller then runs numba's dispatcher or numpy, as without this module). Loaded once per
    process, by whichever thread asks first."""
    with _LOAD_LOCK:
        return _classifier_once()


_LOAD_LOCK = threading.Lock()


@functools.lru_cache(maxsize=None)
def _classifier_once() -> NativeClassifier | None:
    if kernel_choice() != "auto":
        return None
    try:
        key = cache_key()
        if key is None:
            return None
        for directory in cache_dirs():
            if _paths(directory, key)[2].exists():  # marked unusable
                return None
            loaded = _load_from(directory, key)
            if loaded is not None:
                return loaded
    except Exception:
        pass
    return None


def _load_from(directory: Path, key: str) -> NativeClassifier | None:
    """The classifier saved in one cache directory for ``key``, or None (none there, or a
    damaged file: the next directory may hold a good one)."""
    obj_path, meta_path, _ = _paths(directory, key)
    try:
        meta = json.loads(meta_path.read_text())
        if isinstance(meta, dict) and meta.get("key") == key:
            return _load_object(obj_path, meta)
    except Exception:
        pass
    return None


#: ``BOUNCE_KERNEL``'s values: the basin kernel's route
KERNEL_CHOICES = ("auto", "numba", "numpy")


@functools.lru_cache(maxsize=None)
def numba_installed() -> bool:
    """numba is installed (found without importing it), looked up once per process:
    ``find_spec`` takes the import lock, which a kernel's tile in a thread must never wait
    for (the main thread imports meanwhile, and an interrupt in one of its imports once left
    the lock held: the tiles waited for ever)."""
    return importlib.util.find_spec("numba") is not None


def kernel_choice() -> str:
    """``BOUNCE_KERNEL``: "auto" (unset or empty: the saved machine code, else numba's
    dispatcher, else numpy), "numba" (numba's dispatcher) or "numpy" (numpy's code); any
    other value is a ConfigError."""
    value = os.environ.get("BOUNCE_KERNEL", "").strip().lower() or "auto"
    if value not in KERNEL_CHOICES:
        from ..errors import ConfigError

        raise ConfigError(f"environment variable BOUNCE_KERNEL={os.environ['BOUNCE_KERNEL']!r}: "
                          f"expected one of {', '.join(KERNEL_CHOICES)}")
    return value


def classify_arrays(theta0: np.ndarray, v0: np.ndarray, params: ModelParams, fp: FixedPoint,
                    max_iterations: int, tolerance: float, min_hop_s: float,
                    max_steps: int) -> tuple[np.ndarray, np.ndarray]:
    """(outcome int8, iterations int16) of flat float arrays, as
    ``compiled.classify_arrays`` (the same bits): by the saved machine code where there is
    one (``classifier``), else by numba's dispatcher."""
    native = classifier()
    if native is None:
        from .compiled import classify_arrays as by_numba

        return by_numba(theta0, v0, params, fp, max_iterations, tolerance, min_hop_s,
                        max_steps)
    return native(*kernel_inputs(theta0, v0, params, fp, tolerance, min_hop_s),
                  max_iterations, max_steps)


def _check_grid(model: tuple[float, float, float, float]):
    """The verification's grid (a 90 x 60 grid of Fig. 4's extent and states that cannot
    fly) and its settings: (theta0, v0, params, fp, max_iterations, tolerance, min_hop,
    max_steps)."""
    alpha, g, amplitude, period = model
    params = ModelParams(alpha=alpha, g=g, racket_amplitude=amplitude, racket_period=period)
    theta, v = np.meshgrid(np.linspace(-np.pi, 3 * np.pi, 90), np.linspace(-1.0, 8.0, 60))
    return (theta.ravel(), v.ravel(), params, params.fixed_point(), 120, 1e-3, 1e-3, 60)


def _classify_check_grids(classify: Callable[..., tuple[np.ndarray, np.ndarray]]) -> str:
    """The verification grids' outcomes and impact counts, as hex (for comparison)."""
    parts = []
    for model in _CHECK_MODELS:
        outcome, iterations = classify(*_check_grid(model))
        parts.append(outcome.tobytes().hex() + iterations.tobytes().hex())
    return ":".join(parts)


def _check_in_this_process(obj_path: str, meta_path: str) -> None:
    """The verification's child: load the object without numba, classify the grids, print
    the result (``build_classifier``)."""
    native = _load_object(Path(obj_path), json.loads(Path(meta_path).read_text()))
    if native is None:
        raise SystemExit("the object did not load")

    def classify(theta0, v0, params, fp, max_iterations, tolerance, min_hop, max_steps):
        return native(theta0, v0, solver_constants(params, fp, tolerance, min_hop),
                      max_iterations, max_steps)

    result = _classify_check_grids(classify)
    if "numba" in sys.modules:
        raise SystemExit("numba was imported")
    print(result)


def build_classifier() -> bool:
    """Compile ``compiled.classify_entry`` with numba as a C-callable function, check its
    object code in a fresh process (module docstring) and save it for ``classifier``.
    Returns whether it is saved. Where it cannot be used (not an ELF object, numba refusing
    the function, a failed check) the key is marked unusable (``classify-<key>.unusable``
    in the cache directory, with the reason; delete it to try again), so that later runs
    neither try again nor pay for the compilation: numba's dispatcher runs. Where no cache
    directory can be written nothing is compiled. Never raises: this only saves time. Needs
    numba; about a second, once per key."""
    try:
        return _build(cache_key())
    except Exception:
        return False


def _build(key: str | None) -> bool:
    if key is None or kernel_choice() != "auto" or classifier() is not None:
        return False
    if any(_paths(directory, key)[2].exists() for directory in cache_dirs()):
        return False  # marked unusable
    directory = _writable_cache_dir()
    if directory is None:
        return False
    obj_path, meta_path, unusable = _paths(directory, key)
    try:
        code, meta = _compile_entry(key)
    except Exception as exc:  # numba refused: a later numba may not; its key is another
        unusable.write_text(f"numba could not compile the entry: {type(exc).__name__}: {exc}\n")
        return False
    if meta is None:
        unusable.write_text("not a 64-bit little-endian ELF object (Linux only)\n")
        return False
    from . import compiled

    expected = _classify_check_grids(compiled.classify_arrays)
    _remove_stale_staging(directory)
    with tempfile.TemporaryDirectory(dir=directory, prefix=_STAGING) as staging:
        tmp_obj, tmp_meta = Path(staging) / "k.o", Path(staging) / "k.json"
        tmp_obj.write_bytes(code)
        tmp_meta.write_text(json.dumps(meta))
        ok, reason = _verify(tmp_obj, tmp_meta, expected)
        if ok is None:  # the check could not run here (another bounce_cli): try next time
            return False
        if not ok:
            unusable.write_text(reason + "\n")
            return False
        os.replace(tmp_obj, obj_path)
        os.replace(tmp_meta, meta_path)  # last: the object is complete before it
    _classifier_once.cache_clear()
    return True


#: the prefix of a build's temporary folder in the cache directory
_STAGING = "classify-staging-"


def _writable_cache_dir() -> Path | None:
    """The first cache directory this process can write (created if missing), or None."""
    for directory in cache_dirs():
        try:
            directory.mkdir(parents=True, exist_ok=True)
            with tempfile.TemporaryFile(dir=directory):
                return directory
        except OSError:
            continue
    return None


def _remove_stale_staging(directory: Path) -> None:
    """Temporary folders of builds killed an hour or more ago (SIGKILL leaves them)."""
    import shutil
    import time

    for folder in directory.glob(_STAGING + "*"):
        try:
            if time.time() - folder.stat().st_mtime > 3600:
                shutil.rmtree(folder, ignore_errors=True)
        except OSError:
            pass


def _compile_entry(key: str) -> tuple[bytes, dict | None]:
    """(object code, metadata) of ``compiled.classify_entry`` compiled by numba as a cfunc;
    metadata None where the object is not ELF (``undefined_symbols``)."""
    from numba import cfunc, types

    from . import compiled

    signature = types.void(*(types.CPointer(getattr(types, t)) if k == "p" else getattr(types, t)
                             for k, t in _ENTRY_ARGS))
    options: dict[str, Any] = {"nopython": True, "nogil": True, "error_model": "numpy"}
    with compiled.numba_without_blas():
        entry: Any = cfunc(signature, **options)(compiled.classify_entry)
    code = entry._library.serialize_using_object_code()[2][0]  # numba's CodeLibrary
    undefined = undefined_symbols(code)
    if undefined is None:
        return code, None
    return code, {"key": key, "symbol": entry.native_name, "undefined": undefined,
                  "sha256": hashlib.sha256(code).hexdigest()}


#: the check's child: isolated (``-I``: neither the working directory nor PYTHONPATH on its
#: path, which could hold another bounce_cli or shadow the standard library), with this
#: bounce_cli's folder added where the installation does not hold it already
_CHECK = ("import sys\n"
          "root = sys.argv[1]\n"
          "if root not in sys.path:\n"
          "    sys.path.insert(0, root)\n"
          "from bounce_cli.model import native\n"
          "print(native.__file__)\n"
          "native._check_in_this_process(sys.argv[2], sys.argv[3])\n")


def _verify(obj_path: Path, meta_path: Path, expected: str) -> tuple[bool | None, str]:
    """(passed, reason) of the object's check in a fresh Python process; passed is None
    where the child imported another bounce_cli than this one (nothing is decided)."""
    root = str(Path(__file__).resolve().parents[2])
    command = [sys.executable, "-I", "-c", _CHECK, root, str(obj_path), str(meta_path)]
    try:
        done = subprocess.run(command, capture_output=True, text=True, timeout=120)
    except subprocess.TimeoutExpired:
        return False, "the check timed out"
    if done.returncode != 0:
        return False, f"the check failed (exit {done.returncode}): {done.stderr.strip()[-300:]}"
    where, _, result = done.stdout.strip().partition("\n")
    if Path(where).resolve() != Path(__file__).resolve():
        return None, f"the check imported {where}"
    if result.strip() != expected:
        return False, "the check's outcomes differ from numba's"
    return True, ""
