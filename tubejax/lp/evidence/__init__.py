"""Evidence: float64 certificates and verdicts confirmed by HiGHS (SPEC section 4)."""
