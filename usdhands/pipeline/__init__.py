"""Pipeline integration: USD schema plugin registration and hooks for host applications."""
