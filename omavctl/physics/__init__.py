"""Physics of the omav: rigid body, allocation, controller, named effects."""
