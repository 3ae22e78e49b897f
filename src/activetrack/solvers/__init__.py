"""The single-sensor problem's solvers: the analytic optimum of Section IV-A
(KKT conditions, Sylvester resultant, companion eigenvalues) and the numerical solver
used where the analytic one does not apply.
"""
