"""Stages 2 to 4 and the moves between cuts: the program as machine poses and joint-space blocks.

``poses`` (part frame + work offset -> table frame, tool lengths), ``branch`` (working-mode IK,
one tool-axis angle pair per cutting run), ``linearise`` (blocks within the CL tolerances) and
``safe_motion`` (the moves between cuts: retract, reposition, plunge).
"""
