"""A fuzzing campaign over habitsim's readers and command line: a developer tool kept
with the tests, not shipped in the package.

Run it with ``make fuzz`` (``FUZZ_N=…`` inputs, default 10,000) or, from ``tests/``,
``python -m fuzzing [--n N] [--seed S] [--targets bvh,npz,...] [--show K] [--check]``.
The generators and the runner are in :mod:`fuzzing.campaign`; ``tests/test_fuzz.py``
drives the same generators with hypothesis and runs a short campaign.
"""
