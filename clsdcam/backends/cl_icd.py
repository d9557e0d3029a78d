"""OpenCL implementations beside pyopencl's PoCL, and the environment that lists them all together.

The ICD loader lists one platform per ``.icd`` file (one line: the implementation's library) in the folder
``OCL_ICD_VENDORS`` names (else /etc/OpenCL/vendors). The loader inside pyopencl's wheel also reads the
``.icd`` files beside it, where ``pocl-binary-distribution`` puts PoCL's: PoCL stays listed whatever the
variable says. Two implementations install without a usable ICD file:

* Intel's CPU runtime from PyPI (``pip install intel-opencl-rt intel-cmplr-lib-rt``): ``<prefix>/lib/libintelocl.so``,
  which loads its companions from ``<prefix>/lib`` (LD_LIBRARY_PATH; the ``.icd`` it ships names its build
  machine's path);
* Oclgrind (``apt-get install oclgrind``): ``<prefix>/lib/oclgrind/liboclgrind-rt-icd.so``, an OpenCL 1.2 device that
  interprets kernels and checks them (``OCLGRIND_*`` variables).

The loader reads these variables once, when pyopencl loads: they take effect in a new process. From a shell:
``eval "$(python -m clsdcam.backends.cl_icd DIR)"`` writes the folder DIR and exports them; names after DIR
(``intel``, ``oclgrind``) list those alone beside the system's.
"""
from __future__ import annotations

import os
import shutil
import sys
from pathlib import Path

SYSTEM_VENDORS = Path("/etc/OpenCL/vendors")
OCLGRIND_ICD = Path("lib/oclgrind/liboclgrind-rt-icd.so")
INSTALL = {"intel": "pip install intel-opencl-rt intel-cmplr-lib-rt", "oclgrind": "apt-get install oclgrind"}


def library(name: str) -> Path | None:
    """The ICD library of ``intel`` (this environment's) or ``oclgrind`` (beside the ``oclgrind`` command), if there."""
    if name == "intel":
        candidates = [Path(sys.prefix) / "lib" / "libintelocl.so"]
    elif name == "oclgrind":
        command = shutil.which("oclgrind")
        candidates = [Path(command).resolve().parents[1] / OCLGRIND_ICD] if command else []
        candidates.append(Path("/usr") / OCLGRIND_ICD)
    else:
        raise ValueError(f"unknown OpenCL implementation {name!r}: expected one of {', '.join(INSTALL)}")
    return next((path for path in candidates if path.is_file()), None)


def vendors_environment(folder: Path, names=tuple(INSTALL)) -> dict[str, str]:
    """Write into ``folder`` the system's ``.icd`` files and one for each of ``names`` that is installed; return
    the variables that make the loader list them (with PoCL): OCL_ICD_VENDORS, and LD_LIBRARY_PATH for Intel's."""
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    for icd in sorted(SYSTEM_VENDORS.glob("*.icd")) if SYSTEM_VENDORS.is_dir() else []:
        shutil.copy(icd, folder / icd.name)
    env = {"OCL_ICD_VENDORS": str(folder)}
    for name in names:
        path = library(name)
        if path is not None:
            (folder / f"clsdcam-{name}.icd").write_text(f"{path}\n")
            if name == "intel":
                env["LD_LIBRARY_PATH"] = os.pathsep.join(p for p in (str(path.parent), os.environ.get("LD_LIBRARY_PATH"))
                                                         if p)
    return env


def main(argv=None) -> int:
    """``python -m clsdcam.backends.cl_icd DIR [NAME ...]``: write DIR (every implementation of :data:`INSTALL`, or
    the NAMEs), print the ``export`` lines for a shell's eval."""
    argv = sys.argv[1:] if argv is None else argv
    unknown = [name for name in argv[1:] if name not in INSTALL]
    if not argv or unknown:
        print(f"usage: python -m clsdcam.backends.cl_icd DIR [{' '.join(INSTALL)}]   (eval its output in a shell)"
              + (f"; unknown: {' '.join(unknown)}" if unknown else ""), file=sys.stderr)
        return 2
    for name, value in vendors_environment(Path(argv[0]), tuple(argv[1:]) or tuple(INSTALL)).items():
        print(f"export {name}='{value}'")
    return 0


if __name__ == "__main__":
    sys.exit(main())
