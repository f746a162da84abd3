"""The bundled seed arms: URDF files and the DH descriptions they are generated from (installed as ``planner.urdf``)."""
