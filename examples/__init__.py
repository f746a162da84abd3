"""Example plan files shipped with the package (``planner examples`` lists and copies them)."""
