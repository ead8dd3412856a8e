"""The flight phases, in order: preflight, takeoff, search, return. Each owns the tasks it
starts (a TaskGroup) and ends in its documented safe action (see ``mission.controller``)."""
