"""The paper's evaluation of TRACE, above the simulator and the investigator.

``evaluation.baselines`` measures TRACE against post-hoc explanation methods on simulator
runs; ``evaluation.cli`` assembles the ``trace-sim`` program (the simulator's commands and
``baselines``).
"""
