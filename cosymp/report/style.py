"""One colour per method, used by the app and by both reports.

Structure-preserving methods are drawn in cool colours (blues, greens, violets), the methods that
preserve nothing in warm ones (red, orange, brown, pink), the exact flow and scipy's solvers in
greys. A method keeps its colour in every view, table and report.
"""
METHOD_COLORS = {
    "midpoint": "#1864ab", "symplectic-euler": "#0c8599", "theta": "#5f3dc4", "gauss4": "#2b8a3e",
    "gauss6": "#0b4f1c", "composition4": "#7048e8", "composition6": "#3b1e8c", "boris": "#087f5b",
    "euler": "#8c564b", "rk4": "#e03131", "rk8": "#f08c00", "theta-naive": "#e64980",
    "exact": "#495057", "scipy-RK45": "#868e96", "scipy-DOP853": "#212529", "scipy-LSODA": "#adb5bd",
}
OTHER = "#343a40"
"""The colour of a second curve whose method has the same colour as the first (drawn dashed)."""
GAUGE_COLORS = {"original": "#212529", "coulomb": "#1864ab", "symmetric": "#2b8a3e", "landau": "#e8590c",
                "lorenz": "#9c36b5"}


def method_color(name):
    """The colour of a method or solver name (a θ-method's name may carry its θ: 'theta(0.3)')."""
    return METHOD_COLORS.get(name, METHOD_COLORS.get(name.split("(")[0], OTHER))


def pair_colors(first, second):
    """The colours of two compared methods: each its own, or OTHER for the second when they match."""
    a, b = method_color(first), method_color(second)
    return a, (OTHER if b == a else b)
