"""blurtrap.data"""
