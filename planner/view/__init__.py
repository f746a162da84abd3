"""An interactive 3-D view of an arm and its plans in the browser (needs the ``view`` extra: viser).

It sits just below :mod:`planner.app` and imports only the layers under it::

    from planner import load_robot
    from planner.view import Scene

    scene = Scene(load_robot("dh3"), port=8080)  # open scene.url in a browser
    scene.set_q([0.3, 0.5, -0.8])
    scene.serve_forever()

viser is imported when a :class:`Scene` is made; without it the error names the extra
(``pip install 'servo-arm-planner[view]'``).
"""

from planner.view.scene import Scene, require_viser

__all__ = ["Scene", "require_viser"]
