"""How a sensor moves: its reachable set in one step (eq. 13-16, Lemma 3, Fig. 3),
the projection of a wanted position onto it, and actions to moves.
"""
