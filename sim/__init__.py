"""The built-in simulator: a PX4-like MAVLink multirotor and simulated VHF radios.

Run it as ``python -m sim MISSION.yaml``; see sim/README.md. It talks to the ground station
only over MAVLink (UDP) and detection wire format v1 (UDP), like real hardware.
"""
