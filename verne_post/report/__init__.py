"""What a post reports besides the program: the HTML report (``html``).
"""
