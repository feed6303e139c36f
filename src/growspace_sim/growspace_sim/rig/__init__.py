"""Experiments on a chamber that last days: a run directory, a journal, a runner that resumes.

Modules: ``rundir`` (the run directory and its journal; pure, files only), ``policies`` (the
policies a run uses and the simulated twin the oracle acts on), ``runner`` (the loop, the
journal and the recording reconciled on resume), ``chambers`` (sim_node started by the runner,
or an attached chamber, over the Gymnasium bridge's ``ChamberLink``) and ``cli``
(``growspace-rig``).
"""
