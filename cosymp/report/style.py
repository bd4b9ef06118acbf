"""One colour and one marker per method, used by the app and by both reports.

Every method has a colour of its own, far from the colour of every method that can share a plot
with it (a work-precision plot shows every method of a scene at once, with scipy's solvers;
tests/test_report.py checks the CIEDE2000 distance of every such pair against MIN_DISTANCE). The
colours go by family: the non-preserving Runge-Kutta methods warm (red, orange, brown), the
paper's lifted θ-methods blues, Gauss-Legendre greens, the midpoint compositions violets, the
splittings what is left (yellow, olive, grey-green, pink, maroon, mauve); the exact flow near black, scipy's
solvers black and greys. Each family also has its own marker (scipy's solvers are drawn dashed as
well), so that two methods whose colours come closest still differ in shape. The two methods of
the first view keep the classic pair: implicit midpoint blue, RK4 red. A method keeps its colour
and marker in every view, table and report.
"""
from functools import cache

METHOD_COLORS = {
    "midpoint": "#1864ab", "symplectic-euler": "#38c0c0", "theta": "#a898f8", "theta-naive": "#20a8f8",
    "gauss4": "#386000", "gauss6": "#00c030", "composition4": "#6800d8", "composition6": "#f008e0",
    "boris": "#a09000", "euler": "#f88000", "rk4": "#e03131", "rk8": "#803000", "leapfrog": "#c0b000",
    "yoshida4": "#689070", "yoshida6": "#f890a8", "blanes-moan4": "#800030", "blanes-moan6": "#886810",
    "mclachlan8": "#805888", "aba864": "#005850",
    "exact": "#212529", "scipy-RK45": "#6c6c6c", "scipy-DOP853": "#000000", "scipy-LSODA": "#b0b0b0",
}
MIN_DISTANCE = 21
"""The least CIEDE2000 distance between the colours of two methods that can share a plot. The
four pairs of the previous palette that read alike in a work-precision plot were 11 to 20.5 apart
(gauss4 and boris, composition4 and blanes-moan6, rk4 and composition6, symplectic-euler and
leapfrog); a search of the colours visible on white (L* 25 to 72) found no 19 that all keep more
than about 23. With mclachlan8 no colour kept 21 from all the others: the splittings' six were
searched again together (coordinate descent over that grid), moving the five older ones slightly.
aba864 (modulated only) took the grid's colour farthest from the others of that scene: 22.7."""
OTHER = "#343a40"
"""The colour of a second curve whose method has the same colour as the first (drawn dashed)."""
FAMILY_MARKERS = {"Explicit": "triangle", "Theta": "circle", "Gauss": "diamond", "Composition": "inverted_triangle",
                  "Splitting": "hex", "Perturbed": "x", "Boris": "star", "Exact": "plus", "scipy": "square"}
"""The marker of each family of methods (the kernel family a method's data belongs to, and scipy's
solvers), as Bokeh names them; the reports draw the same shapes."""
GAUGE_COLORS = {"original": "#212529", "coulomb": "#1864ab", "symmetric": "#2b8a3e", "landau": "#e8590c",
                "lorenz": "#9c36b5"}


def _base(name):
    """A method or solver name without a θ-method's θ ('theta(0.3)' -> 'theta')."""
    return name.split("(")[0]


def method_color(name):
    """The colour of a method or solver name (a θ-method's name may carry its θ: 'theta(0.3)')."""
    return METHOD_COLORS.get(name, METHOD_COLORS.get(_base(name), OTHER))


@cache
def method_marker(name):
    """The marker of a method's family or of scipy's solvers ('circle' for a name that is neither)."""
    from ..methods import METHODS

    base = _base(name)
    if base.startswith("scipy-"):
        return FAMILY_MARKERS["scipy"]
    return FAMILY_MARKERS.get(type(METHODS[base].data()).__name__, "circle") if base in METHODS else "circle"


def pair_colors(first, second):
    """The colours of two compared methods: each its own, or OTHER for the second when they match."""
    a, b = method_color(first), method_color(second)
    return a, (OTHER if b == a else b)
