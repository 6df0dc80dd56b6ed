# Exact Mie series at 50 digits (mpmath) for small-x reference cases: independent truth.
import mpmath as mp
mp.mp.dps = 50
def series(m, x, perfect=False):
    x = mp.mpf(x); N = int(x + 4.05*x**(mp.mpf(1)/3) + 2) + 10
    def psi(n, z): return z*mp.sqrt(mp.pi/(2*z))*mp.besselj(n+mp.mpf(1)/2, z)
    def eta(n, z): return z*mp.sqrt(mp.pi/(2*z))*mp.bessely(n+mp.mpf(1)/2, z)
    a=[];b=[]
    for n in range(1, N+1):
        px, pxm = psi(n,x), psi(n-1,x)
        xi, xim = px + 1j*eta(n,x), pxm + 1j*eta(n-1,x)
        if perfect:
            a.append((n/x*px - pxm)/(n/x*xi - xim)); b.append(px/xi)
        else:
            mx = m*x
            D = mp.diff(lambda t: psi(n,t), mx)/psi(n,mx)
            t1 = D/m + n/x; t2 = D*m + n/x
            a.append((t1*px-pxm)/(t1*xi-xim)); b.append((t2*px-pxm)/(t2*xi-xim))
    qext = 2/x**2*sum((2*n+1)*mp.re(a[n-1]+b[n-1]) for n in range(1,N+1))
    qsca = 2/x**2*sum((2*n+1)*(abs(a[n-1])**2+abs(b[n-1])**2) for n in range(1,N+1))
    gq = 4/x**2*sum(n*(n+2)/mp.mpf(n+1)*mp.re(a[n-1]*mp.conj(a[n])+b[n-1]*mp.conj(b[n])) + (2*n+1)/mp.mpf(n*(n+1))*mp.re(a[n-1]*mp.conj(b[n-1])) for n in range(1,N))
    return qext, qsca, gq/qsca
for name, m, x, pc in [("MIEV0_case1", 0, 0.099, True), ("MIEV0_case2", 0, 0.101, True), ("MIEV0_case5", mp.mpf('0.75'), 0.099, False), ("MIEV0_case6", mp.mpf('0.75'), 0.101, False)]:
    qe, qs, g = series(m, x, pc)
    print(name, mp.nstr(qe, 15), mp.nstr(qs, 15), mp.nstr(g, 15))
