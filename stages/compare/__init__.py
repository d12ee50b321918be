"""Equal-budget comparison of LiveScene and the baselines on one dataset (``livescene compare``).

Downstream of the model and evaluation stages (it trains with one and scores with the other), so neither
of them imports it.
"""
