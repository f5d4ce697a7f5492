"""The feed planner's parts (:mod:`verne_post.planning.feed_planner` is the entry and tells the
method): ``plan`` (the result), ``segments`` (many sequences in one array, splines), ``batch``
(one call's sequences and caps, one-block plans), ``grid`` (gridpoints and caps), ``rounds``
(the planner), ``profiles`` (the time law), ``verification`` (a plan against every limit),
``scurve`` (S-curves of short moves) and ``lp`` (the third-order programme's plans)."""
