"""The bodies: arms, the robot registry, the manipulated object, kinematics.

Arms loaded into Pinocchio (one or many as one model), the robot registry, the rigid object
and its convex shape, frame kinematics and inverse kinematics.
"""
