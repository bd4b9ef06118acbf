/* Plain C mirror of cosymp's numba core, the reference `cosymp bench` measures it against.

   Same formulas, loops and generic dense solve as cosymp/kernels (loops.py, families.py,
   linear.py, linalg.py) and cosymp/scenes, so a ratio measures the compilers, not the
   algorithms: linear scenes step by the step's matrix (M, Q, s) built once per step
   (propagate_matrix), the others by the family's member step with Newton (propagate_one).
   One build per scene, one entry point per family:

     -DSCENE=DECAYING|DAMPED|MODULATED|CHARGED|KAPITZA  -DNDOF=n -DNCOEF=k -DLINEAR=0|1

   The sizes numba knows when it compiles (state size, coefficient count, the stage count of a
   Gauss tableau and of an explicit one of at most 4 stages) are compile-time constants here too; the other families' data (tableau, weights,
   gammas, offsets, and so the number of stages and offsets) arrive at run time as arrays, as
   numba receives them. Scene parameters
   are held by value, as numba holds its named tuple. The charged scene is the paper's
   beta(t) = B0 (1 + eps sin(w t)). */
#include <math.h>
#include <stdlib.h>

#define DECAYING 1
#define DAMPED 2
#define MODULATED 3
#define CHARGED 4
#define KAPITZA 5

#if !defined(SCENE) || !defined(NDOF) || !defined(NCOEF) || !defined(LINEAR)
#error "build with -DSCENE -DNDOF -DNCOEF -DLINEAR"
#endif

#define M (2 * NDOF)

/* numba compiles every kernel function force-inlined into its loop (kernels.dispatch.INLINE) */
#define INLINE static inline __attribute__((always_inline))

enum { OK, OVERFLOW, NEWTON, SINGULAR };
enum { EXPLICIT, THETA, GAUSS, COMPOSITION, BORIS, EXACT };

#define NEWTON_MAX 50
#define NEWTON_TOL 4e-15

/* ---- scenes: the parameter tuple in field order, and the kernel functions; a coefficient
   row is c = C + r * NCOEF, numba's C[r, :] ---- */

#if SCENE == DECAYING
typedef struct { double lam; } Params;
#elif SCENE == DAMPED
typedef struct { double m, w0, gamma; } Params;
#elif SCENE == MODULATED
typedef struct { double eps, alpha; } Params;
#elif SCENE == CHARGED
typedef struct { double m, e, B0, eps, w, C00, C01, C11, d; } Params;
#elif SCENE == KAPITZA
typedef struct { double w0, a, nu; } Params;
#else
#error "unknown SCENE"
#endif

#if SCENE == KAPITZA

INLINE void coef(const Params *P, double t, double *c)
{
    c[0] = P->w0 * P->w0 - P->a * P->nu * P->nu * cos(P->nu * t);
    c[1] = P->a * P->nu * P->nu * P->nu * sin(P->nu * t);
}

INLINE void grad(const double *c, const double *z, double *g)
{
    g[0] = c[0] * sin(z[0]);
    g[1] = z[1];
}

INLINE void hess(const double *c, const double *z, double *Hm)
{
    Hm[0] = c[0] * cos(z[0]);
    Hm[1] = Hm[2] = 0.0;
    Hm[3] = 1.0;
}

INLINE double dhdt(const double *c, const double *z)
{
    return -c[1] * cos(z[0]);
}

#else /* quadratic scenes (scenes/quadratic.py): c = (S, dS/dt, s, ds/dt, J S), S row-major */

#define JS (2 * M * M + 2) /* where finish stores J S in a coefficient row */

/* quadratic.clear: zero S, dS/dt, s and ds/dt (finish writes all of J S) */
INLINE void fill_zero(double *c)
{
    for (int i = 0; i < JS; i++)
        c[i] = 0.0;
}

/* quadratic.finish: append J S, (J S)[i] = S[n + i], (J S)[n + i] = -S[i] */
INLINE void finish(double *c)
{
    for (int i = 0; i < NDOF; i++) {
        for (int j = 0; j < M; j++) {
            c[JS + i * M + j] = c[(NDOF + i) * M + j];
            c[JS + (NDOF + i) * M + j] = -c[i * M + j];
        }
    }
}

INLINE double dhdt(const double *c, const double *z)
{
    double acc = -0.0;
    for (int i = 0; i < M; i++) {
        double row = c[M * M + i * M] * z[0];
        for (int j = 1; j < M; j++)
            row += c[M * M + i * M + j] * z[j];
        acc += z[i] * row;
    }
    return 0.5 * acc + c[2 * M * M + 1];
}

#endif

#if SCENE == DECAYING

INLINE void coef(const Params *P, double t, double *c)
{
    double a = exp(-P->lam * t);
    fill_zero(c);
    c[0] = c[3] = a;
    c[4] = c[7] = -P->lam * a;
    finish(c);
}

#define HAS_FLOW
INLINE void flow(const Params *P, double t0, double t1, double *z)
{
    double angle = -exp(-P->lam * t0) * expm1(-P->lam * (t1 - t0)) / P->lam;
    double c = cos(angle);
    double s = sin(angle);
    double q = z[0];
    z[0] = c * q + s * z[1];
    z[1] = -s * q + c * z[1];
}

#elif SCENE == DAMPED

INLINE void coef(const Params *P, double t, double *c)
{
    double grow = exp(P->gamma * t);
    double kin = grow / P->m;
    double pot = P->m * P->w0 / grow;
    fill_zero(c);
    c[0] = pot;
    c[3] = kin;
    c[4] = -P->gamma * pot;
    c[7] = P->gamma * kin;
    finish(c);
}

#define HAS_FLOW
INLINE void flow(const Params *P, double t0, double t1, double *z)
{
    double s = t1 - t0;
    double W2 = P->w0 - 0.25 * P->gamma * P->gamma;
    double C, S;
    if (W2 > 0.0) {
        double W = sqrt(W2);
        C = cos(W * s);
        S = sin(W * s) / W;
    } else if (W2 < 0.0) {
        double W = sqrt(-W2);
        C = cosh(W * s);
        S = sinh(W * s) / W;
    } else {
        C = 1.0;
        S = s;
    }
    double q = z[0], p = z[1];
    double root = exp(0.5 * P->gamma * t0);
    double half = exp(0.5 * P->gamma * s);
    z[0] = half * (q * C + (root * (root * p) / P->m - 0.5 * P->gamma * q) * S);
    z[1] = (p * C + (0.5 * P->gamma * p - P->m * P->w0 * (q / root) / root) * S) / half;
}

/* damped.scaling: E = 2^e nearest to e^{gamma t/2} (rint: half to even, as numpy's rint) */
#define HAS_SCALING
INLINE long scaling(const Params *P, double t, double *tau)
{
    if (P->gamma == 0.0) {
        *tau = 0.0;
        return 0;
    }
    long e = (long)rint(P->gamma * t * (0.5 / M_LN2));
    *tau = (double)e * (2.0 * M_LN2) / P->gamma;
    return e;
}

#elif SCENE == MODULATED

INLINE void coef(const Params *P, double t, double *c)
{
    fill_zero(c);
    c[0] = 1.0 + P->eps * sin(P->alpha * t);
    c[3] = 1.0;
    c[4] = P->eps * P->alpha * cos(P->alpha * t);
    finish(c);
}

#elif SCENE == CHARGED

#define BETA (3 * M * M + 2) /* beta, beta' after the quadratic coefficients */

INLINE void coef(const Params *P, double t, double *c)
{
    double s = sin(P->w * t);
    double b0 = P->B0 * (1.0 + P->eps * s);
    double b1 = P->B0 * P->eps * P->w * cos(P->w * t);
    double b2 = -P->B0 * P->eps * P->w * P->w * s;
    const double G[2][2] = {{P->C00, P->C01}, {P->C01, P->C11}};
    const double Kc[2][2] = {{1.0 + P->C00, -1.0 + P->C01}, {1.0 + P->C01, 1.0 + P->C11}};
    double inv = 1.0 / P->m;
    for (int i = 0; i < 2; i++) {
        for (int j = 0; j < 2; j++) {
            double LL = 0.0;
            for (int k = 0; k < 2; k++)
                LL += Kc[k][i] * Kc[k][j];
            double e2 = P->e * P->e;
            c[i * 4 + j] = e2 * b0 * b0 * LL * inv - P->e * b1 * G[i][j];
            c[16 + i * 4 + j] = 2.0 * e2 * b0 * b1 * LL * inv - P->e * b2 * G[i][j];
            c[i * 4 + 2 + j] = -P->e * b0 * Kc[j][i] * inv;
            c[16 + i * 4 + 2 + j] = -P->e * b1 * Kc[j][i] * inv;
            c[(2 + i) * 4 + j] = -P->e * b0 * Kc[i][j] * inv;
            c[16 + (2 + i) * 4 + j] = -P->e * b1 * Kc[i][j] * inv;
            c[(2 + i) * 4 + 2 + j] = i == j ? inv : 0.0;
            c[16 + (2 + i) * 4 + 2 + j] = 0.0;
        }
    }
    c[32] = -P->e * P->d * b0;
    c[33] = -P->e * P->d * b1;
    finish(c);
    c[BETA] = b0;
    c[BETA + 1] = b1;
}

#define HAS_FIELDS
INLINE void vecpot(const Params *P, const double *c, const double *q, double *A)
{
    A[0] = c[BETA] * ((1.0 + P->C00) * q[0] + (-1.0 + P->C01) * q[1]);
    A[1] = c[BETA] * ((1.0 + P->C01) * q[0] + (1.0 + P->C11) * q[1]);
}

INLINE void efield(const double *c, const double *q, double *E)
{
    E[0] = -c[BETA + 1] * (q[0] - q[1]);
    E[1] = -c[BETA + 1] * (q[0] + q[1]);
}

INLINE double bfield(const Params *P, const double *c)
{
    return c[BETA] * ((1.0 + P->C01) - (-1.0 + P->C01));
}

#endif

#ifndef HAS_SCALING
/* scenes.base.unscaled */
INLINE long scaling(const Params *P, double t, double *tau)
{
    (void)P;
    (void)t;
    *tau = 0.0;
    return 0;
}
#endif

/* loops._rescale: q <- q qf, p <- p pf unless e = 0 (qf, pf = 2^e, 2^-e or the reverse) */
INLINE void rescale(double *z, long e, double qf, double pf)
{
    if (e != 0)
        for (int i = 0; i < NDOF; i++) {
            z[i] *= qf;
            z[NDOF + i] *= pf;
        }
}

/* ---- linalg.solve: the leading n x n block of A (row stride n) against B (n x k, row stride
   k; k = 1 is a vector); partial pivoting, A destroyed ---- */

INLINE int solve(double *A, double *B, int n, int k)
{
    for (int c = 0; c < n; c++) {
        int p = c;
        double big = fabs(A[c * n + c]);
        for (int i = c + 1; i < n; i++) {
            double v = fabs(A[i * n + c]);
            if (v > big) {
                big = v;
                p = i;
            }
        }
        if (big == 0.0)
            return 0;
        if (p != c) {
            for (int j = c; j < n; j++) {
                double a = A[c * n + j];
                A[c * n + j] = A[p * n + j];
                A[p * n + j] = a;
            }
            for (int j = 0; j < k; j++) {
                double b = B[c * k + j];
                B[c * k + j] = B[p * k + j];
                B[p * k + j] = b;
            }
        }
        double inv = 1.0 / A[c * n + c];
        for (int i = c + 1; i < n; i++) {
            double f = A[i * n + c] * inv;
            if (f != 0.0) {
                for (int j = c + 1; j < n; j++)
                    A[i * n + j] -= f * A[c * n + j];
                for (int j = 0; j < k; j++)
                    B[i * k + j] += -f * B[c * k + j];
            }
        }
    }
    for (int c = n - 1; c >= 0; c--) {
        for (int j = c + 1; j < n; j++) {
            double f = -A[c * n + j];
            for (int x = 0; x < k; x++)
                B[c * k + x] += f * B[j * k + x];
        }
        double f = 1.0 / A[c * n + c];
        for (int x = 0; x < k; x++)
            B[c * k + x] *= f;
    }
    return 1;
}

/* ---- the family's data as numba receives them (arrays and their lengths), and the scratch
   whose size depends on the number of stages, allocated once per run like numba's work ---- */

typedef struct {
    const double *A, *b, *gammas, *offsets;
    const long *stage;
    int s, u; /* stages (len(b) or len(gammas)) and time offsets */
    double wq0, wq1, wp0, wp1;
} Family;

typedef struct {
    double *K, *Zs, *Fs, *F, *Jm;
} Work;

#if !LINEAR

/* ---- member steps (families.py), for scenes that are not quadratic ---- */

/* _newton_done: whether Newton has converged; *prev receives the correction's size. */
INLINE int newton_done(const double *dz, int ndz, const double *z, int nz, double *prev)
{
    double size = 1.0;
    for (int i = 0; i < nz; i++) {
        double a = fabs(z[i]);
        size = a > size ? a : size;
    }
    double corr = 0.0;
    for (int i = 0; i < ndz; i++) {
        double a = fabs(dz[i]);
        corr = a > corr ? a : corr;
    }
    int done = corr <= NEWTON_TOL * size || (corr <= 1e-10 * size && corr >= 0.5 * *prev);
    *prev = corr;
    return done;
}

INLINE int theta_core(const double *c, double h, double wq0, double wq1, double wp0, double wp1,
                             double *z, double *pt)
{
    double z1[M], Zt[M], g[M], F[M], Hm[M * M], Jm[M * M];
    for (int i = 0; i < M; i++)
        z1[i] = z[i];
    double prev = INFINITY;
    int status = NEWTON;
    for (int it = 0; it < NEWTON_MAX; it++) {
        for (int i = 0; i < NDOF; i++) {
            Zt[i] = wq0 * z[i] + wq1 * z1[i];
            Zt[NDOF + i] = wp0 * z[NDOF + i] + wp1 * z1[NDOF + i];
        }
        grad(c, Zt, g);
        hess(c, Zt, Hm);
        for (int i = 0; i < NDOF; i++) {
            F[i] = z[i] - z1[i] + h * g[NDOF + i];
            F[NDOF + i] = z[NDOF + i] - z1[NDOF + i] - h * g[i];
        }
        for (int i = 0; i < NDOF; i++) {
            for (int j = 0; j < M; j++) {
                double w = j < NDOF ? wq1 : wp1;
                Jm[i * M + j] = -h * w * Hm[(NDOF + i) * M + j];
                Jm[(NDOF + i) * M + j] = h * w * Hm[i * M + j];
            }
        }
        for (int i = 0; i < M; i++)
            Jm[i * M + i] += 1.0;
        if (!solve(Jm, F, M, 1)) {
            status = SINGULAR;
            break;
        }
        for (int i = 0; i < M; i++)
            z1[i] += F[i];
        if (newton_done(F, M, z1, M, &prev)) {
            status = OK;
            break;
        }
    }
    if (status == OK) {
        for (int i = 0; i < NDOF; i++) {
            Zt[i] = wq0 * z[i] + wq1 * z1[i];
            Zt[NDOF + i] = wp0 * z[NDOF + i] + wp1 * z1[NDOF + i];
        }
        *pt = *pt - h * dhdt(c, Zt);
        for (int i = 0; i < M; i++)
            z[i] = z1[i];
    }
    return status;
}

INLINE int composition_step(const Family *D, const double *C, double h, double *z, double *pt)
{
    int status = OK;
    for (int i = 0; i < D->s; i++) {
        status = theta_core(C + i * NCOEF, D->gammas[i] * h, 0.5, 0.5, 0.5, 0.5, z, pt);
        if (status != OK)
            break;
    }
    return status;
}

INLINE int explicit_step(const Family *D, const Work *W, const double *C, double h, double *z,
                                double *pt)
{
    double *K = W->K;
    double Y[M], g[M];
    int s = D->s;
    double dpt = -0.0;
    for (int i = 0; i < s; i++) {
        for (int r = 0; r < M; r++)
            Y[r] = z[r];
        for (int j = 0; j < i; j++) {
            double a = h * D->A[i * s + j];
            if (a != 0.0)
                for (int r = 0; r < M; r++)
                    Y[r] += a * K[j * M + r];
        }
        grad(C + D->stage[i] * NCOEF, Y, g);
        for (int r = 0; r < NDOF; r++) {
            K[i * M + r] = g[NDOF + r];
            K[i * M + NDOF + r] = -g[r];
        }
        dpt += D->b[i] * dhdt(C + D->stage[i] * NCOEF, Y);
    }
    for (int i = 0; i < s; i++) {
        double bh = h * D->b[i];
        for (int r = 0; r < M; r++)
            z[r] += bh * K[i * M + r];
    }
    *pt = *pt - h * dpt;
    return OK;
}

INLINE int gauss_step(const Family *D, const Work *W, const double *C, double h, double *z,
                             double *pt)
{
    double *Zs = W->Zs, *Fs = W->Fs, *F = W->F, *Jm = W->Jm;
    double y[M], g[M], Hm[M * M];
    int s = D->s, sm = D->s * M;
    for (int i = 0; i < s; i++)
        for (int r = 0; r < M; r++)
            Zs[i * M + r] = z[r];
    double prev = INFINITY;
    int status = NEWTON;
    for (int it = 0; it < NEWTON_MAX; it++) {
        for (int j = 0; j < s; j++) {
            for (int r = 0; r < M; r++)
                y[r] = Zs[j * M + r];
            grad(C + j * NCOEF, y, g);
            for (int r = 0; r < NDOF; r++) {
                Fs[j * M + r] = g[NDOF + r];
                Fs[j * M + NDOF + r] = -g[r];
            }
        }
        for (int i = 0; i < s; i++) {
            for (int r = 0; r < M; r++) {
                double acc = z[r] - Zs[i * M + r];
                for (int j = 0; j < s; j++)
                    acc += h * D->A[i * s + j] * Fs[j * M + r];
                F[i * M + r] = acc;
            }
        }
        for (int j = 0; j < s; j++) {
            for (int r = 0; r < M; r++)
                y[r] = Zs[j * M + r];
            hess(C + j * NCOEF, y, Hm);
            for (int i = 0; i < s; i++) {
                double a = h * D->A[i * s + j];
                for (int r = 0; r < NDOF; r++) {
                    for (int c = 0; c < M; c++) {
                        Jm[(i * M + r) * sm + j * M + c] = -a * Hm[(NDOF + r) * M + c];
                        Jm[(i * M + NDOF + r) * sm + j * M + c] = a * Hm[r * M + c];
                    }
                }
            }
        }
        for (int r = 0; r < sm; r++)
            Jm[r * sm + r] += 1.0;
        if (!solve(Jm, F, sm, 1)) {
            status = SINGULAR;
            break;
        }
        for (int i = 0; i < s; i++)
            for (int r = 0; r < M; r++)
                Zs[i * M + r] += F[i * M + r];
        if (newton_done(F, sm, z, M, &prev)) {
            status = OK;
            break;
        }
    }
    if (status == OK) {
        double dpt = -0.0;
        for (int j = 0; j < s; j++) {
            for (int r = 0; r < M; r++)
                y[r] = Zs[j * M + r];
            grad(C + j * NCOEF, y, g);
            double bh = h * D->b[j];
            for (int r = 0; r < NDOF; r++) {
                z[r] += bh * g[NDOF + r];
                z[NDOF + r] -= bh * g[r];
            }
            dpt += D->b[j] * dhdt(C + j * NCOEF, y);
        }
        *pt = *pt - h * dpt;
    }
    return status;
}

INLINE int step(int family, const Family *D, const Work *W,
                                                      const double *C, double h, double *z, double *pt)
{
    switch (family) {
    case EXPLICIT:
        return explicit_step(D, W, C, h, z, pt);
    case THETA:
        return theta_core(C, h, D->wq0, D->wq1, D->wp0, D->wp1, z, pt);
    case GAUSS:
        return gauss_step(D, W, C, h, z, pt);
    default:
        return composition_step(D, C, h, z, pt);
    }
}

#else /* LINEAR */

/* ---- step matrices (linear.py): z' = M z, p_t' = p_t - (z.Q z / 2 + s) ---- */

/* (J S)[i, j], stored in the coefficient row c by finish */
INLINE double js(const double *c, int i, int j)
{
    return c[JS + i * M + j];
}

INLINE double sdot(const double *c, int i, int j)
{
    return c[M * M + i * M + j];
}

INLINE double sdot0(const double *c)
{
    return c[2 * M * M + 1];
}

INLINE void identity(double *A)
{
    for (int i = 0; i < M; i++)
        for (int c = 0; c < M; c++)
            A[i * M + c] = i == c ? 1.0 : 0.0;
}

INLINE void zero(double *A)
{
    for (int i = 0; i < M * M; i++)
        A[i] = 0.0;
}

/* out = scale * op(A) B (op(A) = A^T if transpose_a), or out += that if add */
INLINE void product(const double *A, const double *B, double *out, int transpose_a, double scale,
                           int add)
{
    for (int i = 0; i < M; i++) {
        for (int j = 0; j < M; j++) {
            double acc = 0.0;
            for (int r = 0; r < M; r++)
                acc += (transpose_a ? A[r * M + i] : A[i * M + r]) * B[r * M + j];
            out[i * M + j] = add ? out[i * M + j] + scale * acc : scale * acc;
        }
    }
}

/* Q += scale * G^T (dS/dt) G, with T an M x M scratch */
INLINE void add_sandwich(double *Q, const double *G, const double *c, double scale, double *T)
{
    for (int i = 0; i < M; i++) {
        for (int j = 0; j < M; j++) {
            double acc = 0.0;
            for (int r = 0; r < M; r++)
                acc += sdot(c, i, r) * G[r * M + j];
            T[i * M + j] = acc;
        }
    }
    product(G, T, Q, 1, scale, 1);
}

/* (I - h J S W1) M = I + h J S W0, N = W0 + W1 M, Q = h N^T S' N; returns s = h s' */
INLINE double theta_matrix(const double *c, double h, double wq0, double wq1, double wp0,
                                  double wp1, double *Mm, double *Q, double *A, double *N)
{
    for (int i = 0; i < M; i++) {
        for (int j = 0; j < M; j++) {
            double a = h * js(c, i, j);
            double d = i == j ? 1.0 : 0.0;
            A[i * M + j] = d - a * (j < NDOF ? wq1 : wp1);
            Mm[i * M + j] = d + a * (j < NDOF ? wq0 : wp0);
        }
    }
    solve(A, Mm, M, M);
    for (int i = 0; i < M; i++) {
        double w0 = i < NDOF ? wq0 : wp0, w1 = i < NDOF ? wq1 : wp1;
        for (int j = 0; j < M; j++)
            N[i * M + j] = w1 * Mm[i * M + j] + (i == j ? w0 : 0.0);
    }
    zero(Q);
    add_sandwich(Q, N, c, h, A);
    return h * sdot0(c);
}

/* (M, Q, s) <- (M1, Q1, s1) after (M, Q, s) */
INLINE double compose(double *Mm, double *Q, double s, const double *M1, const double *Q1,
                             double s1, double *T)
{
    product(Q1, Mm, T, 0, 1.0, 0);
    product(Mm, T, Q, 1, 1.0, 1);
    product(M1, Mm, T, 0, 1.0, 0);
    for (int i = 0; i < M * M; i++)
        Mm[i] = T[i];
    return s + s1;
}

INLINE double theta_lmatrix(const Family *D, const double *C, double h, double *Mm, double *Q)
{
    double A[M * M], N[M * M];
    return theta_matrix(C, h, D->wq0, D->wq1, D->wp0, D->wp1, Mm, Q, A, N);
}

INLINE double composition_lmatrix(const Family *D, const double *C, double h, double *Mm,
                                         double *Q)
{
    double W0[M * M], W1[M * M], M1[M * M], Q1[M * M], T[M * M];
    identity(Mm);
    zero(Q);
    double s = 0.0;
    for (int i = 0; i < D->s; i++) {
        double s1 = theta_matrix(C + i * NCOEF, D->gammas[i] * h, 0.5, 0.5, 0.5, 0.5, M1, Q1, W0, W1);
        s = compose(Mm, Q, s, M1, Q1, s1, T);
    }
    return s;
}

/* stage maps G_i = I + h sum_j a_ij J S_j G_j (one solve), M = I + h sum_j b_j J S_j G_j */
INLINE double gauss_lmatrix(const Family *D, const Work *W, const double *C, double h,
                                   double *Mm, double *Q)
{
    double *Big = W->Jm, *G = W->K;
    double V[M * M];
    int s = D->s, sm = D->s * M;
    for (int i = 0; i < s; i++)
        for (int j = 0; j < s; j++)
            for (int r = 0; r < M; r++)
                for (int c = 0; c < M; c++)
                    Big[(i * M + r) * sm + j * M + c] = (i == j && r == c ? 1.0 : 0.0)
                        - h * D->A[i * s + j] * js(C + j * NCOEF, r, c);
    for (int r = 0; r < sm; r++)
        for (int c = 0; c < M; c++)
            G[r * M + c] = r % M == c ? 1.0 : 0.0;
    solve(Big, G, sm, M);
    identity(Mm);
    zero(Q);
    double total = 0.0;
    for (int j = 0; j < s; j++) {
        double hb = h * D->b[j];
        for (int i = 0; i < M; i++) {
            for (int c = 0; c < M; c++) {
                double acc = 0.0;
                for (int r = 0; r < M; r++)
                    acc += js(C + j * NCOEF, i, r) * G[(j * M + r) * M + c];
                Mm[i * M + c] += hb * acc;
            }
        }
        add_sandwich(Q, G + j * M * M, C + j * NCOEF, hb, V);
        total += hb * sdot0(C + j * NCOEF);
    }
    return total;
}

/* stage maps G_i = I + h sum_(j<i) a_ij K_j with K_j = J S_j G_j; M = I + h sum b_i K_i */
INLINE double explicit_lmatrix(const Family *D, const Work *W, const double *C, double h,
                                      double *Mm, double *Q)
{
    double *K = W->K;
    double G[M * M], T[M * M];
    int s = D->s;
    identity(Mm);
    zero(Q);
    double total = 0.0;
    for (int i = 0; i < s; i++) {
        const double *c = C + D->stage[i] * NCOEF;
        identity(G);
        for (int j = 0; j < i; j++) {
            double a = h * D->A[i * s + j];
            if (a != 0.0)
                for (int r = 0; r < M * M; r++)
                    G[r] += a * K[j * M * M + r];
        }
        for (int r = 0; r < M; r++) {
            for (int x = 0; x < M; x++) {
                double acc = 0.0;
                for (int y = 0; y < M; y++)
                    acc += js(c, r, y) * G[y * M + x];
                K[(i * M + r) * M + x] = acc;
            }
        }
        double hb = h * D->b[i];
        for (int r = 0; r < M * M; r++)
            Mm[r] += hb * K[i * M * M + r];
        add_sandwich(Q, G, c, hb, T);
        total += hb * sdot0(c);
    }
    return total;
}

#ifdef HAS_FLOW
/* columns of M from the flow; p_t from H + p_t conserved: Q = M^T S(t+h) M - S(t) */
INLINE double exact_lmatrix(const Params *P, const double *C, double t, double h, double *Mm,
                                   double *Q)
{
    double S1M[M * M], v[M];
    for (int c = 0; c < M; c++) {
        for (int r = 0; r < M; r++)
            v[r] = r == c ? 1.0 : 0.0;
        flow(P, t, t + h, v);
        for (int r = 0; r < M; r++)
            Mm[r * M + c] = v[r];
    }
    for (int i = 0; i < M; i++) {
        for (int c = 0; c < M; c++) {
            double acc = 0.0;
            for (int r = 0; r < M; r++)
                acc += C[NCOEF + i * M + r] * Mm[r * M + c];
            S1M[i * M + c] = acc;
        }
    }
    product(Mm, S1M, Q, 1, 1.0, 0);
    for (int i = 0; i < M; i++)
        for (int c = 0; c < M; c++)
            Q[i * M + c] -= C[i * M + c];
    return C[NCOEF + 2 * M * M] - C[2 * M * M];
}
#endif

#ifdef HAS_FIELDS
/* boris_core: drift-kick-drift in (q, v), v = (p - e A) / m, fields at the half step; the
   half-step state (q, p) is left in zh. */
INLINE double boris_core(const Params *P, const double *C, double h, double *z, double pt,
                                double *zh)
{
    double q[2], v[2], A[2], E[2];
    double a = P->e * h / (2.0 * P->m);
    vecpot(P, C, z, A);
    double v0x = (z[2] - P->e * A[0]) / P->m;
    double v0y = (z[3] - P->e * A[1]) / P->m;
    q[0] = z[0] + 0.5 * h * v0x;
    q[1] = z[1] + 0.5 * h * v0y;
    efield(C + NCOEF, q, E);
    double tau = a * bfield(P, C + NCOEF);
    double sig = 2.0 * tau / (1.0 + tau * tau);
    double vx = v0x + a * E[0];
    double vy = v0y + a * E[1];
    double wx = vx + vy * tau;
    double wy = vy - vx * tau;
    vx += wy * sig;
    vy -= wx * sig;
    v[0] = vx + a * E[0];
    v[1] = vy + a * E[1];
    vecpot(P, C + NCOEF, q, A);
    zh[0] = q[0];
    zh[1] = q[1];
    zh[2] = 0.5 * P->m * (v0x + v[0]) + P->e * A[0];
    zh[3] = 0.5 * P->m * (v0y + v[1]) + P->e * A[1];
    pt = pt - h * dhdt(C + NCOEF, zh);
    z[0] = q[0] + 0.5 * h * v[0];
    z[1] = q[1] + 0.5 * h * v[1];
    vecpot(P, C + 2 * NCOEF, z, A);
    z[2] = P->m * v[0] + P->e * A[0];
    z[3] = P->m * v[1] + P->e * A[1];
    return pt;
}

/* columns of M and of the half-step map N (z_half = N z) from the push of unit vectors;
   Q = h N^T S'(t + h/2) N */
INLINE double boris_lmatrix(const Params *P, const double *C, double h, double *Mm, double *Q)
{
    double N[M * M], T[M * M], v[M], zh[M];
    for (int c = 0; c < M; c++) {
        for (int r = 0; r < M; r++)
            v[r] = r == c ? 1.0 : 0.0;
        boris_core(P, C, h, v, 0.0, zh);
        for (int r = 0; r < M; r++) {
            Mm[r * M + c] = v[r];
            N[r * M + c] = zh[r];
        }
    }
    zero(Q);
    add_sandwich(Q, N, C + NCOEF, h, T);
    return h * sdot0(C + NCOEF);
}
#endif

INLINE double lmatrix(int family, const Family *D, const Work *W,
                                                            const Params *P, const double *C, double t,
                                                            double h, double *Mm, double *Q)
{
    switch (family) {
    case EXPLICIT:
        return explicit_lmatrix(D, W, C, h, Mm, Q);
    case THETA:
        return theta_lmatrix(D, C, h, Mm, Q);
    case GAUSS:
        return gauss_lmatrix(D, W, C, h, Mm, Q);
    case COMPOSITION:
        return composition_lmatrix(D, C, h, Mm, Q);
#ifdef HAS_FLOW
    case EXACT:
        return exact_lmatrix(P, C, t, h, Mm, Q);
#endif
#ifdef HAS_FIELDS
    case BORIS:
        return boris_lmatrix(P, C, h, Mm, Q);
#endif
    default:
        (void)P;
        (void)t;
        return NAN;
    }
}

#endif /* LINEAR */

/* ---- loops.py: propagate_matrix (linear scenes) and propagate_one (the others) ---- */

/* the loop's arguments; done receives the steps completed */
typedef struct {
    double t0, h;
    double *Z, *PT;
    long N, m, nsteps, stride;
    double *Trec, *Zrec, *PTrec, *dZrec;
    long ndz; /* rows of dZrec: 0 records no increments */
    long done;
} Loop;

INLINE long coefs(const Params *P, const Family *D, double tk, double tk1, double h, double *C,
                  int reuse, long prev, double *tau)
{
    long e = scaling(P, tk, tau);
    int u = D->u;
    for (int j = 0; j < u; j++) {
        if (j == 0 && reuse && e == prev)
            for (int c = 0; c < NCOEF; c++)
                C[c] = C[(u - 1) * NCOEF + c];
        else
            coef(P, (D->offsets[j] == 1.0 ? tk1 : tk + D->offsets[j] * h) - *tau, C + j * NCOEF);
    }
    return e;
}

/* loops._step_start: step k's scaling and time coefficients; the scaling's factors change
   with its exponent only */
INLINE long step_start(const Params *P, const Family *D, double t0, double h, long k, double *C,
                       int can_reuse, long *prev, double *up, double *down, double *tau)
{
    long e = coefs(P, D, t0 + k * h, t0 + (k + 1) * h, h, C, can_reuse && k > 0, *prev, tau);
    if (e != *prev) {
        *up = ldexp(1.0, (int)e);
        *down = ldexp(1.0, (int)-e);
        *prev = e;
    }
    return e;
}

/* loops._add: Kahan's compensated sum of p_t's increments, (sum, compensation) per member;
   p_t = sum - compensation */
INLINE void add(double S, double Cc, double d, double *sum, double *comp)
{
    double y = d - Cc, s = S + y;
    *comp = (s - S) - y;
    *sum = s;
}

/* loops._finite: pt and z all finite, by one comparison (0 x is NaN for x infinite or NaN) */
INLINE int all_finite(double pt, const double *z)
{
    double nan = 0.0 * pt;
    for (int r = 0; r < M; r++)
        nan += 0.0 * z[r];
    return nan == 0.0;
}

/* _accept: check the member's new state, store it, record it */
INLINE int accept(int status, long i, const double *z, const double *old, double pt, Loop *L,
                         long rec, int recording)
{
    long N = L->N, ld = L->m;
    if (status == OK && !all_finite(pt, z))
        status = OVERFLOW;
    if (status == OK) {
        L->PT[i] = pt;
        for (int r = 0; r < M; r++)
            L->Z[i * ld + r] = z[r];
        if (recording) {
            L->PTrec[rec * N + i] = pt;
            for (int r = 0; r < M; r++) {
                L->Zrec[(rec * N + i) * ld + r] = z[r];
                if (L->ndz > 0)
                    L->dZrec[(rec * N + i) * ld + r] = z[r] - old[r];
            }
        }
    }
    return status;
}

#if !LINEAR
/* loops._one_loop: a single member, its state, p_t and p_t's compensation kept in locals from
   step to step and stored on return (the last good state where a step fails) */
INLINE int propagate_one(int family, const Family *D, const Work *W, const Params *P, Loop *Lp)
{
    Loop L = *Lp;
    double t0 = L.t0, h = L.h;
    double C[D->u * NCOEF], z[M], old[M];
    int can_reuse = D->u > 1 && D->offsets[0] == 0.0 && D->offsets[D->u - 1] == 1.0;
    L.Trec[0] = t0;
    L.PTrec[0] = L.PT[0];
    for (int r = 0; r < M; r++) {
        L.Zrec[r] = L.Z[r];
        if (L.ndz > 0)
            L.dZrec[r] = NAN;
        z[r] = L.Z[r];
    }
    double pt = L.PT[0], S = pt, Cc = 0.0;
    long rec = 1, prev = 0, due = L.stride, ld = L.m;
    double up = 1.0, down = 1.0;
    for (long k = 0; k < L.nsteps; k++) {
        double tau;
        long e = step_start(P, D, t0, h, k, C, can_reuse, &prev, &up, &down, &tau);
        for (int r = 0; r < M; r++)
            old[r] = z[r];
        double dpt = -0.0, sum, comp;
        rescale(z, e, down, up);
        int status = step(family, D, W, C, h, z, &dpt);
        rescale(z, e, up, down);
        add(S, Cc, dpt, &sum, &comp);
        if (status == OK && !all_finite(sum, z))
            status = OVERFLOW;
        if (status != OK) {
            L.PT[0] = pt;
            for (int r = 0; r < M; r++)
                L.Z[r] = old[r];
            Lp->done = k;
            return status;
        }
        S = sum;
        Cc = comp;
        pt = sum - comp;
        if (--due == 0 || k + 1 == L.nsteps) {
            L.PTrec[rec] = pt;
            for (int r = 0; r < M; r++) {
                L.Zrec[rec * ld + r] = z[r];
                if (L.ndz > 0)
                    L.dZrec[rec * ld + r] = z[r] - old[r];
            }
            L.Trec[rec] = t0 + (k + 1) * h;
            rec += 1;
            due = L.stride;
        }
    }
    L.PT[0] = pt;
    for (int r = 0; r < M; r++)
        L.Z[r] = z[r];
    Lp->done = L.nsteps;
    return OK;
}
#endif

INLINE int propagate(int family, const Family *D, const Work *W,
                                                           const Params *P, Loop *Lp)
{
#if !LINEAR
    /* one trajectory: cosymp runs an ensemble of a nonlinear scene in its fused loop
       (kernels/survey.py), which this file does not mirror and `cosymp bench` does not time */
    return propagate_one(family, D, W, P, Lp);
#else
    Loop L = *Lp;
    double t0 = L.t0, h = L.h;
    long ld = L.m;
    double C[D->u * NCOEF], z[M], old[M], zs[M];
    int can_reuse = D->u > 1 && D->offsets[0] == 0.0 && D->offsets[D->u - 1] == 1.0;
    double Mm[M * M], Q[M * M];
    L.Trec[0] = t0;
    for (long i = 0; i < L.N; i++) {
        L.PTrec[i] = L.PT[i];
        for (int r = 0; r < M; r++) {
            L.Zrec[i * ld + r] = L.Z[i * ld + r];
            if (L.ndz > 0)
                L.dZrec[i * ld + r] = NAN;
        }
    }
    double *S = malloc(L.N * sizeof(double)), *Cc = malloc(L.N * sizeof(double));
    for (long i = 0; i < L.N; i++) {
        S[i] = L.PT[i];
        Cc[i] = 0.0;
    }
    long rec = 1, prev = 0;
    double up = 1.0, down = 1.0;
    for (long k = 0; k < L.nsteps; k++) {
        double tau;
        long e = step_start(P, D, t0, h, k, C, can_reuse, &prev, &up, &down, &tau);
        double tk = t0 + k * h - tau;
        double s = lmatrix(family, D, W, P, C, tk, h, Mm, Q);
        int recording = (k + 1) % L.stride == 0 || k + 1 == L.nsteps;
        for (long i = 0; i < L.N; i++) {
            double quad = 0.0;
            for (int r = 0; r < M; r++) {
                old[r] = L.Z[i * ld + r];
                zs[r] = old[r];
            }
            rescale(zs, e, down, up);
            for (int r = 0; r < M; r++) {
                double acc = 0.0, qr = 0.0;
                for (int c = 0; c < M; c++) {
                    acc += Mm[r * M + c] * zs[c];
                    qr += Q[r * M + c] * zs[c];
                }
                z[r] = acc;
                quad += zs[r] * qr;
            }
            rescale(z, e, up, down);
            double sum, comp;
            add(S[i], Cc[i], -(0.5 * quad + s), &sum, &comp);
            int status = accept(OK, i, z, old, sum - comp, &L, rec, recording);
            if (status != OK) {
                free(S);
                free(Cc);
                Lp->done = k;
                return status;
            }
            S[i] = sum;
            Cc[i] = comp;
        }
        if (recording) {
            L.Trec[rec] = t0 + (k + 1) * h;
            rec += 1;
        }
    }
    free(S);
    free(Cc);
    Lp->done = L.nsteps;
    return OK;
#endif
}

/* ---- entry points, one per family: the scene's parameters by value, the family's arrays ---- */

INLINE int explicit_run(Loop *L, const double *params, const double *offsets, int u, const double *A,
                        const double *b, const long *stage, int s)
{
    Params P = *(const Params *)params;
    Family D = {.offsets = offsets, .u = u};
    D.A = A;
    D.b = b;
    D.stage = stage;
    D.s = s;
    double K[LINEAR ? s * M * M : s * M];
    Work W = {.K = K};
    return propagate(EXPLICIT, &D, &W, &P, L);
}

/* numba compiles a tableau of at most 4 stages per (stages, nodes) (methods.FIXED_STAGES: its
   data are tuples): so is this, for the registered ones (Euler, RK4); longer ones at run time */
int run_explicit(Loop *L, const double *params, const double *offsets, long u, const double *A,
                 const double *b, const long *stage, long s)
{
    if (s == 1 && u == 1)
        return explicit_run(L, params, offsets, 1, A, b, stage, 1);
    if (s == 4 && u == 3)
        return explicit_run(L, params, offsets, 3, A, b, stage, 4);
    return explicit_run(L, params, offsets, (int)u, A, b, stage, (int)s);
}

INLINE int gauss_run(Loop *L, const double *params, const double *offsets, const double *A,
                     const double *b, int s)
{
    Params P = *(const Params *)params;
    Family D = {.offsets = offsets, .u = s};
    D.A = A;
    D.b = b;
    D.s = s;
    double K[s * M * M], Zs[s * M], Fs[s * M], F[s * M], Jm[s * M * s * M];
    Work W = {.K = K, .Zs = Zs, .Fs = Fs, .F = F, .Jm = Jm};
    return propagate(GAUSS, &D, &W, &P, L);
}

/* numba compiles a Gauss tableau per stage count (its data are tuples): so is this, per case */
int run_gauss(Loop *L, const double *params, const double *offsets, long u, const double *A,
              const double *b, long s)
{
    (void)u; /* the nodes are the offsets: u = s */
    switch (s) {
    case 2:
        return gauss_run(L, params, offsets, A, b, 2);
    case 3:
        return gauss_run(L, params, offsets, A, b, 3);
    default:
        return gauss_run(L, params, offsets, A, b, (int)s);
    }
}

int run_theta(Loop *L, const double *params, const double *offsets, long u, double wq0, double wq1,
              double wp0, double wp1)
{
    Params P = *(const Params *)params;
    Family D = {.offsets = offsets, .u = (int)u};
    D.wq0 = wq0;
    D.wq1 = wq1;
    D.wp0 = wp0;
    D.wp1 = wp1;
    Work W = {0};
    return propagate(THETA, &D, &W, &P, L);
}

int run_composition(Loop *L, const double *params, const double *offsets, long u, const double *gammas,
                    long s)
{
    Params P = *(const Params *)params;
    Family D = {.offsets = offsets, .u = (int)u};
    D.gammas = gammas;
    D.s = (int)s;
    Work W = {0};
    return propagate(COMPOSITION, &D, &W, &P, L);
}

#if LINEAR && defined(HAS_FLOW)
int run_exact(Loop *L, const double *params, const double *offsets, long u)
{
    Params P = *(const Params *)params;
    Family D = {.offsets = offsets, .u = (int)u};
    Work W = {0};
    return propagate(EXACT, &D, &W, &P, L);
}
#endif

#if LINEAR && defined(HAS_FIELDS)
int run_boris(Loop *L, const double *params, const double *offsets, long u)
{
    Params P = *(const Params *)params;
    Family D = {.offsets = offsets, .u = (int)u};
    Work W = {0};
    return propagate(BORIS, &D, &W, &P, L);
}
#endif
