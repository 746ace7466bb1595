"""Writing files so that an interruption never leaves a half-written one, and reading the
records they hold (shared by the engine's checkpoints and the experiments' outputs)."""

from __future__ import annotations

import os
import tempfile
from pathlib import Path


def _read_umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


# read once, at import: setting the umask to read it opens a moment in which another thread (a
# progress bar's monitor, a tracking backend) would create world-writable files
_UMASK = _read_umask()


def atomic_write(path: Path, write, binary: bool = False) -> None:
    """Call ``write(file)`` on a temporary file beside ``path``, then move it onto ``path``.

    A write that is interrupted leaves ``path`` as it was (and no temporary file behind).
    """
    path, tmp = Path(path), None
    try:  # an error creating the temporary too names the file meant (a read-only folder, a full quota)
        fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
        with (os.fdopen(fd, "wb") if binary else os.fdopen(fd, "w", newline="")) as fh:
            write(fh)
            fh.flush()
            os.fsync(fh.fileno())
        os.chmod(tmp, 0o666 & ~_UMASK)  # mkstemp makes 0600; results are ordinary files
        os.replace(tmp, path)
    except BaseException as err:
        if tmp is not None and os.path.exists(tmp):
            os.unlink(tmp)
        if isinstance(err, OSError) and err.filename != str(path):  # name the file meant, not the temporary
            raise OSError(err.errno, err.strerror or str(err), str(path)) from None
        raise


def flat_keys(record: dict, prefix: str = "") -> dict:
    """A nested record (a run's config.json) as dotted keys: ``{"ppo": {"lr": 3e-4}, "num_updates":
    20}`` → ``{"ppo.lr": 3e-4, "num_updates": 20}``."""
    flat: dict = {}
    for key, value in record.items():
        if isinstance(value, dict):
            flat.update(flat_keys(value, f"{prefix}{key}."))
        else:
            flat[f"{prefix}{key}"] = value
    return flat


def writable(folder: Path) -> bool:
    """Whether a file can be made in ``folder``, found by making (and removing) one: unlike
    ``os.access``, this also says no to root on a read-only file system or a folder of other
    permissions it cannot override."""
    try:
        with tempfile.NamedTemporaryFile(dir=folder, prefix=".remidi-write-probe.", suffix=".tmp"):
            return True
    except OSError:
        return False


def remove_temporaries(folder: Path, names) -> list[Path]:
    """Delete the temporaries that interrupted :func:`atomic_write` calls of ``folder/<name>``, for
    each of ``names``, left behind (``.<name>.<random>.tmp``: SIGKILL, or Ctrl-C's immediate exit,
    stops a write before its rename or its clean-up); returns what was removed. Only for a folder
    no other process is writing."""
    removed = [tmp for name in names for tmp in Path(folder).glob(f".{name}.*.tmp")]
    for tmp in removed:
        tmp.unlink(missing_ok=True)
    return removed


def code_version() -> dict:
    """What code, libraries and device a run used, for its ``config.json``: the git commit of the
    checkout the ``remidi`` package was imported from (``dirty``: uncommitted changes under
    ``src/``), or ``None`` for an installed copy or a copy of the sources that git does not track
    (a package folder inside some other repository), the JAX versions, the kind of the first
    device (results depend on XLA's rounding, which differs between CPU and GPU), and on a CPU the
    cores the process may use and ``XLA_FLAGS`` (XLA's threading changes how sums are split, so
    a run pinned to one core with XLA on one thread need not repeat a two-core run bit for bit)."""
    import subprocess

    import jax
    import jaxlib

    src = Path(__file__).resolve().parent

    def git(*args):
        try:
            done = subprocess.run(["git", "-C", str(src), *args], capture_output=True, text=True, timeout=10)
        except (OSError, subprocess.SubprocessError):
            return None
        return done.stdout.strip() if done.returncode == 0 else None

    commit = git("rev-parse", "HEAD") if git("ls-files", "--error-unmatch", "__init__.py") else None
    dirty = bool(git("status", "--porcelain", "--", str(src.parent))) if commit else None
    import os

    device = jax.devices()[0]
    cores = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count()
    return {"commit": commit, "dirty": dirty, "jax": jax.__version__, "jaxlib": jaxlib.__version__,
            "device": f"{device.platform}: {device.device_kind}", "cpu": cpu_model(), "cpu_cores": cores,
            "xla_flags": os.environ.get("XLA_FLAGS") or None}


def cpu_model() -> str | None:
    """The host CPU's model and widest vector instruction set XLA can use on it, e.g. ``"Intel(R)
    Xeon(R) Processor, AVX-512"``: XLA's CPU kernels round differently per instruction set, so a run
    resumed on another CPU need not repeat bit for bit. ``None`` where ``/proc/cpuinfo`` is absent."""
    try:
        info = Path("/proc/cpuinfo").read_text()
    except OSError:
        return None
    first = info.split("\n\n", 1)[0]  # the first processor's block: every core reports the same
    fields = {k.strip(): v.strip() for k, v in (line.split(":", 1) for line in first.splitlines() if ":" in line)}
    flags = set(fields.get("flags", "").split())
    isa = "AVX-512" if "avx512f" in flags else "AVX2" if "avx2" in flags else "AVX" if "avx" in flags else None
    model = fields.get("model name") or fields.get("Model") or None
    return ", ".join(x for x in (model, isa) if x) or None
