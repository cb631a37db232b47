"""Generator of the license-free default body model (see ``smplx_jax.default_model``).

cage.py     box-modelling a closed quad cage (grids, extrusions, bridges)
skeleton.py anatomical shape parameters and the 55 joint positions
body.py     the body cage: torso, arms, hands, fingers, legs, feet, neck, head, ears
head.py     the head's implicit shape, facial features, landmarks, expression fields
subdiv.py   Catmull-Clark as a sparse operator, triangulation, edge splitting
surface.py  cage -> 10475-vertex surface (fitted subdivision, sculpting)
rig.py      skinning weights and the joint regressor
hands.py    hand pose mean and PCA
assemble.py the SMPL-X arrays
"""
