"""The IQ receiver: radio samples in, calibrated tag pulses out as detection wire format v1.

Sources (`sources`, `rtltcp`, `hardware`) deliver IQ blocks with a sample counter; the tuning
plan (`tuning`) places the mission's tags in the captured band; the channeliser (`channels`)
turns samples into per-tag band energies per frame; the detector (`detector`, thresholds from
`threshold`) finds pulses matched to the tag's pulse width; `calibration` turns their power into
dBm; `pipeline` ties these together with the sample clock, and `output` and `sigmf` send and
record what was heard. No frames here: the receiver knows no positions.
"""
