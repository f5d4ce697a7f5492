"""verne-post's own processes: the helper processes that plan and verify beside the main
process (``helpers``) and the C allocator's settings of its processes (``allocator``).
"""
