"""Stage 7, writing: the G-code writer (``gcode``), the timed CSV of the planned trajectory
(``trajectory``), fast fixed-decimal numbers (``numbers``), numeric tables and JSON (``tables``)
and atomic files (``atomic``: an output is whole or absent).
"""
