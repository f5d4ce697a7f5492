"""Stage 5: everything the machine cannot do, named by CL line, before anything is written.

``limits`` (travel, rod clearance, reach, singularity margins at block ends and between them),
``headroom`` (how far each pose is from each limit) and ``stage`` (stages 3 to 5 run on
table-frame poses: what the pipeline runs per part and placement per candidate offset).
"""
