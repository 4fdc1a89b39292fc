"""Follower laws defined outside the package, for the `module:function` lookup tests."""

CONSTANT_U = 0.3


def constant_law(g_i, g_j, lambda_ij, c1, c2):
    """Ignores every measurement: the follower flies a circle of radius v / CONSTANT_U."""
    return CONSTANT_U


def fast_law(g_i, g_j, lambda_ij, c1, c2):
    """A turn rate far above any agent's limit (to exercise saturation)."""
    return 100.0


def nan_law(g_i, g_j, lambda_ij, c1, c2):
    return float("nan")


def gains_law(g_i, g_j, lambda_ij, c1, c2):
    """Echo the gains and inputs so the binding order can be checked."""
    return 1000.0 * c1 + c2 + 0.001 * (g_i + 10 * g_j + 100 * lambda_ij)


NOT_A_FUNCTION = 3
