"""drillcosim.cosim: orchestration.

``master`` is the generic FMI 2.0 co-simulation master (it knows nothing of drillstrings),
``scenario`` turns a scene into a system and runs it, ``study`` sweeps and predicts stability,
``cli`` parses the command line. Dependencies point one way: cli -> study -> scenario -> master.
"""
