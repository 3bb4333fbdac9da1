"""blurtrap.diagnostics"""
