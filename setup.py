"""Map the top-level code folders into the ``flagtrack`` import namespace.

``daemon/`` -> ``flagtrack.daemon``, ``drivers/`` -> ``flagtrack.drivers``,
``calibration/`` -> ``flagtrack.calibration``, ``client/`` -> ``flagtrack.client``; every subpackage is discovered so that a
plain ``pip install .`` imports everything (checked by tests/unit/test_packaging.py).
"""

from setuptools import find_packages, setup

TOP_FOLDERS = ("daemon", "drivers", "calibration", "client")

package_dir = {f"flagtrack.{top}": top for top in TOP_FOLDERS}
packages = []
for top in TOP_FOLDERS:
    packages.append(f"flagtrack.{top}")
    packages.extend(f"flagtrack.{top}.{sub}" for sub in find_packages(top))

setup(packages=packages, package_dir=package_dir, package_data={"flagtrack.daemon": ["py.typed"]})
