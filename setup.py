"""The package list of habitsim, computed at build time (everything else: pyproject.toml).

The installed ``habitsim`` package is assembled from four source folders (``habitsim/``,
``mjcf_models/``, ``controllers/``, ``evaluation/``; see ``package-dir`` in
pyproject.toml). Their data folders (one per species model, its ``assets/``, each
shipped checkpoint, the evaluator) hold no Python, but setuptools installs data only from
folders listed as packages and warns once per file for every other one. Listing them as
namespace sub-packages, found here so that a new species or checkpoint needs no edit,
keeps ``pip install`` quiet and the wheel complete.
"""

from setuptools import find_namespace_packages, setup

#: Source folder -> name of the installed package.
ROOTS = {
    "habitsim": "habitsim",
    "mjcf_models": "habitsim.mjcf_models",
    "controllers": "habitsim.controllers",
    "evaluation": "habitsim.evaluation",
}


def packages() -> list[str]:
    """Every package and data folder under :data:`ROOTS`, as installed dotted names."""
    out = []
    for folder, name in ROOTS.items():
        out.append(name)
        found = find_namespace_packages(where=folder, exclude=["__pycache__", "*.__pycache__"])
        out += [f"{name}.{p}" for p in found]
    return sorted(out)


if __name__ == "__main__":  # setuptools runs this file as __main__
    setup(packages=packages())
