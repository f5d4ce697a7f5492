"""The proof of a written program: the G-code reader (``gcode_reader``), the RS274 words it
accepts (``rs274``) and the verifier (``verifier``), which replays the program through the
forward kinematics against the CL path and the machine's limits.
"""
