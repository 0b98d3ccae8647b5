"""On top: seeing a robot (``derive view ROBOT``).

:mod:`derive.view.scene` turns a model into what is drawn -- the skeleton, joint axes, frames,
CoM spheres and equivalent-inertia boxes -- with numpy alone, from models.yaml;
:mod:`derive.view.meshes` adds the links' looks (models.yaml ``visual:``: mesh files through
trimesh, the ``viewer`` extra, and primitive shapes);
:mod:`derive.view.page` writes it as one self-contained HTML page (a canvas renderer inline, no
network, no WebGL) and :mod:`derive.view.server` shows it live in viser (the ``viewer`` extra),
with joint sliders, trajectory playback and an IK target.
"""
