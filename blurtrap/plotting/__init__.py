"""blurtrap.plotting"""
