"""What a post reports besides the program: the figures gathered a part at a time and the JSON
report made of them (``figures``), and the HTML report (``html``)."""
