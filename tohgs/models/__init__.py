"""Networks: PointNet++ and the two diffusers (ContactDiffuser, GraspDiffuser)."""
