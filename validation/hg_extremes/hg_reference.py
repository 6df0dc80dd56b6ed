"""Henyey-Greenstein values at extreme asymmetry, in 60-digit arithmetic (mpmath).

Prints, for g = +-(1 - 1e-12), +-(1 - 1e-8), 0.9999 (each the nearest double, taken exactly):
  P(mu) = (1 - g^2)/(1 + g^2 - 2 g mu)^(3/2) at mu = 1, 1 - 2^-40, 0.999, 0, -1 (exact doubles);
  the inverse CDF  mu(u) = (1 + g^2 - s^2)/(2g),  s = (1 - g^2)/(1 - g + 2 g u),  as 1 - mu
  (and 1 + mu for g < 0), at u = 0.1, 0.5, 0.9, 0.999999 (exact doubles).
Output: Rust tuples (g, mu, P) and (g, u, 1 -+ mu) for src/particles/phase.rs's tests.
Usage: python3 validation/hg_extremes/hg_reference.py
"""
from mpmath import mp, mpf

mp.dps = 60
GS = [1 - 1e-12, -(1 - 1e-12), 1 - 1e-8, -(1 - 1e-8), 0.9999]
MUS = [1.0, 1 - 2.0**-40, 0.999, 0.0, -1.0]
US = [0.1, 0.5, 0.9, 0.999999]

print("const HG_VALUES: [(f64, f64, f64); %d] = [" % (len(GS) * len(MUS)))
for g in GS:
    G = mpf(g)
    for mu in MUS:
        p = (1 - G**2) / (1 + G**2 - 2 * G * mpf(mu)) ** mpf(1.5)
        print("    (%r, %r, %s)," % (g, mu, repr(float(p))))
print("];")
print("const HG_SAMPLES: [(f64, f64, f64); %d] = [" % (len(GS) * len(US)))
for g in GS:
    G = mpf(g)
    for u in US:
        U = mpf(u)
        s = (1 - G**2) / (1 - G + 2 * G * U)
        mu = (1 + G**2 - s**2) / (2 * G)
        d = 1 - mu if g > 0 else 1 + mu
        print("    (%r, %r, %s)," % (g, u, repr(float(d))))
print("];")

# The tails F(mu) and 1 - F(mu) of the CDF in mu, F = (1 - g^2)/(2g) [D^-1/2 - 1/(1+g)],
# D = 1 + g^2 - 2 g mu, at mu = cos(theta) for angles theta (exact doubles, in radians) near
# both poles: (g, theta, F, 1 - F) for PhaseFunction::tails (28 Nov 2026).
THETAS = [1e-9, 1e-6, 1e-3, 1.5707963267948966, 3.141591653589793, 3.1415926525897933]
print("const HG_TAILS: [(f64, f64, f64, f64); %d] = [" % (len(GS) * len(THETAS)))
for g in GS:
    G = mpf(g)
    for th in THETAS:
        M = mp.cos(mpf(th))
        F = (1 - G**2) / (2 * G) * (1 / mp.sqrt(1 + G**2 - 2 * G * M) - 1 / (1 + G))
        print("    (%r, %r, %s, %s)," % (g, th, repr(float(F)), repr(float(1 - F))))
print("];")
