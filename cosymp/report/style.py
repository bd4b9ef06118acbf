"""One colour per method, used by the app and by both reports.

Every method has a hue of its own, far from every other method's (a work-precision plot shows
them all at once; tests/test_report.py checks the perceptual distance), the exact flow and
scipy's solvers greys and black. The two methods of the first view keep the classic pair:
implicit midpoint blue, RK4 red. A method keeps its colour in every view, table and report.
"""
METHOD_COLORS = {
    "midpoint": "#1864ab", "symplectic-euler": "#15aabf", "theta": "#862e9c", "gauss4": "#2b8a3e",
    "gauss6": "#94d82d", "composition4": "#9775fa", "composition6": "#d6336c", "boris": "#5c940d",
    "euler": "#8c564b", "rk4": "#e03131", "rk8": "#f08c00", "theta-naive": "#ffa8a8",
    "leapfrog": "#00c6a4", "yoshida4": "#dd22dd", "yoshida6": "#886600", "blanes-moan4": "#ff55cc",
    "blanes-moan6": "#bb88cc", "exact": "#40464d", "scipy-RK45": "#868e96", "scipy-DOP853": "#000000", "scipy-LSODA": "#ced4da",
}
MIN_DISTANCE = 25
"""The least CIE76 distance between two methods' colours (about 2.3 is just noticeable)."""
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
