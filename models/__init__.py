"""The shipped policies as package data of ``rayreach.models``.

pyproject.toml maps this folder to the package, so ``importlib.resources`` finds
``ur5.zip``, ``kr16.zip`` and their ``.json`` in an installed wheel as in a checkout
(``rayreach.planners.drl.shipped_model``). Training runs (``train-*``) stay out of the wheel.
"""
