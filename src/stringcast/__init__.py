"""stringcast: casting manipulation of unknown strings (Tabata et al.).

Stages, in the order of the paper's Fig. 2: ``motion`` (plan) -> ``executor``
(play on the arm or the virtual ``lab``) -> ``video``, ``calibration``, ``sync``,
``tracking`` -> ``evaluation``, ``estimation`` -> ``motion`` again. ``report``
writes the pages; ``cli`` is the command line the Snakemake rules call.
"""
__version__ = "0.1.0"
