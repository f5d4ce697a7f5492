"""Where to clamp the part: the work-offset search (``search``, ``verne-post place`` and
``--work-offset auto``) and the workspace maps (``workspace``). Both call the checking stage
(:mod:`verne_post.checks.stage`), never the pipeline.
"""
