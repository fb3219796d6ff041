"""Every tolerance of the library, in one place, each with its reason."""

#: Relative area below which a face counts as degenerate: a face whose area is
#: smaller than this times the mean face area has no usable frame or Jacobian.
DEGENERATE_AREA_REL = 1e-14

#: Safety factor on the largest flip-free step (Smith & Schaefer 2015): a step
#: of exactly the root makes a triangle's signed area zero, so stop short of it.
MAX_STEP_SAFETY = 0.8

#: Armijo sufficient-decrease constant of the line search.
ARMIJO_C1 = 1e-4

#: Step shrink factor of the backtracking line search.
BACKTRACK_SHRINK = 0.5

#: Largest number of backtracking halvings before the search gives up.
BACKTRACK_MAX = 60

#: Smallest positive singular value difference used in the closed-form SVD;
#: below it σ1 ≈ σ2 and the rotation angle is undefined (its derivative is
#: taken from the safe branch instead).
SVD_EPS = 1e-30

#: Relative residual a direct sparse solve must reach before it is trusted;
#: above it the solve is repeated with SciPy's LU as a check.
SOLVE_RESIDUAL = 1e-8

#: Squared-norm floor inside safe square roots: sqrt(max(x, SAFE_SQRT_FLOOR))
#: keeps gradients finite at x = 0.
SAFE_SQRT_FLOOR = 1e-300

#: Default relative energy decrease below which a minimizer stops.
ENERGY_RTOL = 1e-9

#: Default gradient norm (relative to the initial one) below which a minimizer stops.
GRAD_RTOL = 1e-8

#: Collinearity tolerance of the boundary convexity check: a turn whose sine is
#: smaller than this (relative) still counts as convex (straight).
CONVEX_SIN = 1e-12

#: Relative residual accepted for a Newton direction: the flip-free line search checks
#: every step, so the direction need only be a good descent direction.
NEWTON_RESIDUAL = 1e-6
#: Diagonal shift (relative to the mean diagonal) of a Newton Hessian whose solve missed
#: ``NEWTON_RESIDUAL``: the shifted system is better conditioned, and its solution is still a
#: descent direction, which the line search checks (Levenberg-Marquardt's remedy).
NEWTON_FALLBACK_SHIFT = 1e-6

#: Aspect ``s1 / s2`` of a face's map above which its UV triangle counts as collapsed: not
#: flipped, but numerically a segment, with no texels across.  An energy without a barrier
#: against it (ARAP, conformal, angle) can end there: ARAP with a free boundary crushed 10 of
#: a vase's 3,600 faces to aspects up to 1e11, 400 with its boundary fixed; no barrier energy
#: came near (largest aspect on those maps: symmetric Dirichlet 31, MIPS 4).
COLLAPSED_ASPECT = 1e6
