"""blurtrap.inference"""
