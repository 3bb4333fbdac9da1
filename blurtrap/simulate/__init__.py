"""blurtrap.simulate"""
