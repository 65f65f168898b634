"""The vertical-channel filters of the seed papers and their shared input.

Modules: ``inputs`` (GNSS-aided attitude reference → vertical specific force, the input of
every filter here) and its compiled ``ahrs`` kernel; ``observer1d`` (seed 003), ``loops``
(2nd/3rd-order baro-inertial damping loops), ``adaptive`` (seed 000's adaptive 3rd-order
loop), ``vkf4`` (seed 004's 4-state baro-inertial KF), ``vekf7`` (seed 001's 7-state EKF).
The estimators register under ``observer1d``, ``loop2``, ``loop3``, ``loop3-adaptive``,
``vkf4`` and ``vekf7`` (``vnav_graph.estimators.base``).
"""
