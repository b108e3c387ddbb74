//! Reference motions: DeepMimic clips, their conversion to the humanoid's qpos, and kinematics.
