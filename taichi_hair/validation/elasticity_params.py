"""Physical parameters shared by the validation experiments (Daviet 2023, Fig. 2 caption)."""

#: Human hair: R = 0.05 mm, rho = 1300 kg/m^3, E = 3 GPa, nu = 0.45 (g = 9.81 m/s^2).
HAIR = dict(radius=5.0e-5, density=1300.0, youngs_modulus_bend=3.0e9, poisson_ratio=0.45)
GRAVITY = 9.81
