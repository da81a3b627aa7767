"""Unit constants: the code works in SI (m, N, Pa, kg, s); scripts may write ``0.12 * MPa``."""

m = 1.0
mm = 1.0e-3
cm = 1.0e-2
N = 1.0
kN = 1.0e3
Pa = 1.0
kPa = 1.0e3
MPa = 1.0e6
GPa = 1.0e9
kg = 1.0
s = 1.0
g = 9.81  # standard gravity, m/s^2
